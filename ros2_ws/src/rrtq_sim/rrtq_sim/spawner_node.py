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
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ObstacleArray, PerceptionStatus, RefereeStatus

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Step, StepGate
from rrtq_common.params import declare_config, spin_node
from rrtq_common.world import ObstacleSpec, TrueObstacles
from rrtq_common.world_yaml import WorldSource, load_world
from rrtq_sim.conversions import perception_status_msg, referee_status_msg
from rrtq_sim.perception import Observation, Perception
from rrtq_sim.referee import Referee


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
        self.gate = StepGate([], lockstep=True, ordered=False, resend=self.status_pub.publish,
                             on_step=self.on_odom)
        self.detected_stamp = 0
        subscribe_inputs(self, self.gate, [Input('odom', Odometry, topics.ODOM_TRUTH,
                                                 qos.STREAM)])
        self.publish_map(0)
        self.publish_truth(0, self.perception.take_truth_change())

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
