"""Obstacle spawner: the true world's obstacles, what the robot perceives of them, the referee.

On every step of the true odometry (/odom/truth: the spawner stands on the simulator's
side) the perception core compares truth with the robot's map inside the perception
disc; whenever the map changes, the whole known set is published on /obstacles/detected
(latched, so late joiners get the current map). Every step ends
with /perception/status, which names the stamp of the latest map: a lock-step reader
that sees it equal to the step's stamp knows to wait for that map.

The ground truth (the obstacles that physically exist) goes on /obstacles/truth, latched,
whenever it changes: no node of the robot reads it; it is there so that a recording
can be judged and plotted against the truth alone. An obstacle due to appear near the
robot is held back until the robot is clear of it (``TrueObstacles``). Every step also
ends with /referee/status: the robot's true clearance to what exists and to the bounds
(:class:`rrtq_sim.referee.Referee`), for the recording; no robot node reads it either.

With ``perception.source: scan`` the spawner hands the robot no polygons: on every step a
scan is due (``perception.rate``) it casts the scanner's rays from the true position
against what exists (:class:`rrtq_sim.scan.LaserScanner`; with the MuJoCo plant, MuJoCo's
``mj_multiRay`` in the plant's model) and publishes /scan; the robot's
obstacle mapper writes /obstacles/detected and /perception/status.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ObstacleArray, PerceptionStatus, RefereeStatus
from sensor_msgs.msg import LaserScan

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Step, StepGate, seconds_to_ns
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import RunConfig
from rrtq_common.scan import PerceptionSource, period_steps, scan_due
from rrtq_common.world import ObstacleSpec, TrueObstacles
from rrtq_common.world_yaml import WorldSource, load_world
from rrtq_sim.conversions import perception_status_msg, referee_status_msg
from rrtq_sim.mujoco_model import BaseParameters
from rrtq_sim.mujoco_rays import MujocoRays
from rrtq_sim.perception import Observation, Perception
from rrtq_sim.plant import PlantModel
from rrtq_sim.referee import Referee
from rrtq_sim.scan import LaserScanner, RayCaster, ScanWorld, polygon_rays

SCAN_STREAM = 0x5CA7
"""Mixed into the run's seed for the scan noise: not the stream of any other node's noise."""


class SpawnerNode(Node):
    """Publishes the known obstacle set at start and on every perception event."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('obstacle_spawner', **NODE_OPTIONS, **kwargs)
        world = load_world(declare_config(self, WorldSource).scenario)
        self.perception = Perception(world.obstacles, world.perception_radius,
                                     TrueObstacles.for_scenario(world))
        self.referee = Referee(world.robot_radius, world.bounds)
        self.pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_DETECTED, qos.LATCHED)
        self.status_pub = self.create_publisher(PerceptionStatus, topics.PERCEPTION_STATUS,
                                                qos.STREAM)
        self.truth_pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_TRUTH,
                                               qos.LATCHED)
        self.referee_pub = self.create_publisher(RefereeStatus, topics.REFEREE_STATUS,
                                                 qos.STREAM)
        self.scanner: LaserScanner | None = None
        if world.perception.source is PerceptionSource.SCAN:
            run = declare_config(self, RunConfig, exclude=('lockstep',))
            plant = declare_config(self, ScanWorld)
            # The physics plant's scan is MuJoCo's, in its own model (the base's mass,
            # damping and friction do not change what a ray meets).
            caster: RayCaster = (
                MujocoRays(world.obstacles, BaseParameters(1.0, 0.0, 0.0, world.robot_radius),
                           plant.mjcf) if plant.model is PlantModel.MUJOCO else polygon_rays)
            self.scanner = LaserScanner(world.perception,
                                        np.random.default_rng([run.seed, SCAN_STREAM]), caster)
            self.scan_period = period_steps(world.perception.rate, run.dt)
            self.dt_ns = seconds_to_ns(run.dt)
            self.scan_pub = self.create_publisher(LaserScan, topics.SCAN, qos.STREAM)
        self.gate = StepGate([], lockstep=True, ordered=False, resend=self.resend,
                             on_step=self.on_odom if self.scanner is None else self.on_odom_scan)
        self.detected_stamp = 0
        subscribe_inputs(self, self.gate, [Input('odom', Odometry, topics.ODOM_TRUTH,
                                                 qos.STREAM)])
        if self.scanner is None:
            self.publish_map(0)
        self.publish_truth(0, self.perception.take_truth_change())

    def resend(self, *messages: Any) -> None:
        for msg in messages:
            (self.status_pub if isinstance(msg, PerceptionStatus) else self.scan_pub).publish(msg)

    def on_odom(self, step: Step) -> None:
        odom = step['odom']
        position = conv.odometry_state(odom)[:2]
        seen = self.perception.observe(position, step.stamp_ns * 1e-9)
        self._log(step.stamp_ns * 1e-9, seen)
        if seen.events:
            self.publish_map(step.stamp_ns)
        self.publish_truth(step.stamp_ns, seen.truth)
        self.referee_pub.publish(referee_status_msg(
            odom.header, self.referee.judge(position, self.perception.truth.existing)))
        status = perception_status_msg(odom.header, self.detected_stamp,
                                       len(self.perception.known_ids), seen)
        self.gate.answered(step.stamp_ns, status)
        self.status_pub.publish(status)

    def on_odom_scan(self, step: Step) -> None:
        """A step of ``perception.source: scan``: the truth, the referee, the due scan."""
        assert self.scanner is not None
        odom = step['odom']
        position = conv.odometry_state(odom)[:2]
        existing = self.perception.truth.update(position, step.stamp_ns * 1e-9)
        self.publish_truth(step.stamp_ns, self.perception.take_truth_change())
        self.referee_pub.publish(referee_status_msg(
            odom.header, self.referee.judge(position, existing)))
        if not scan_due(step.stamp_ns, self.dt_ns, self.scan_period):
            self.gate.answered(step.stamp_ns)
            return
        ranges = self.scanner.scan(position, existing)
        scan = conv.laser_scan_msg(step.stamp_ns, ranges, self.scanner.config)
        self.gate.answered(step.stamp_ns, scan)
        self.scan_pub.publish(scan)

    def _log(self, t: float, seen: Observation) -> None:
        for event, oid in seen.events:
            self.get_logger().info(f't={t:.2f} s: obstacle {oid} {event.value}')
        for oid in seen.held:
            self.get_logger().info(f't={t:.2f} s: obstacle {oid} held back: the robot is '
                                   'within its appear clearance')

    def publish_truth(self, stamp: int, existing: Sequence[ObstacleSpec] | None) -> None:
        if existing is not None:
            self.truth_pub.publish(conv.obstacle_array_msg(
                stamp, [(spec.id, spec.polygon) for spec in existing]))

    def publish_map(self, stamp: int) -> None:
        self.pub.publish(conv.obstacle_array_msg(
            stamp, [(spec.id, spec.polygon) for spec in self.perception.known_obstacles()]))
        self.detected_stamp = stamp


def main(args: list[str] | None = None) -> None:
    spin_node(SpawnerNode, args)


if __name__ == '__main__':
    main()
