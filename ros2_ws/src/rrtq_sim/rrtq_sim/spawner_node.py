"""Obstacle spawner: the true world's obstacles, and what the robot perceives of them.

On every /odom step the perception core compares truth with the robot's map inside
the perception disc; whenever the map changes, the whole known set is published on
/obstacles/detected (latched, so late joiners get the current map). Every step ends
with /perception/status, which names the stamp of the latest map: a lock-step reader
that sees it equal to the step's stamp knows to wait for that map.

The ground truth (the obstacles that physically exist) goes on /obstacles/truth, latched,
whenever it changes: no node of the robot reads it; it is there so that a recording
can be judged and plotted against the truth alone. An obstacle due to appear near the
robot is held back until the robot is clear of it (``TrueObstacles``).
"""

from __future__ import annotations

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ObstacleArray, PerceptionStatus

from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.params import declare, spin_node
from rrtq_sim.perception import ObstacleEvent, Perception, TrueObstacles
from rrtq_sim.polygon_set import LivePolygons
from rrtq_sim.scenario import load_scenario


class SpawnerNode(Node):
    """Publishes the known obstacle set at start and on every perception event."""

    def __init__(self, **kwargs) -> None:
        super().__init__('obstacle_spawner', **kwargs)
        scenario = load_scenario(declare(self, 'scenario', '', 'scenario YAML with the '
                                         'obstacles (validated by the orchestrator)'))
        self.specs = {spec.id: spec for spec in scenario.obstacles}
        self.perception = Perception(scenario.obstacles, scenario.perception_radius,
                                     TrueObstacles.for_scenario(scenario))
        self.held: frozenset[str] = frozenset()
        self.existing_shapes = LivePolygons()
        self.pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_DETECTED, qos.LATCHED)
        self.status_pub = self.create_publisher(PerceptionStatus, topics.PERCEPTION_STATUS,
                                                qos.STREAM)
        self.truth_pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_TRUTH,
                                               qos.LATCHED)
        self.last_stamp = -1
        self.detected_stamp = 0
        self.existing: list[str] | None = None
        self.create_subscription(Odometry, topics.ODOM, self.on_odom, qos.STREAM)
        self.publish(0)
        self.publish_truth(0)

    def on_odom(self, msg: Odometry) -> None:
        stamp = conv.stamp_ns(msg.header.stamp)
        if stamp <= self.last_stamp:
            self.status_pub.publish(self.status)   # a resent step: answer it again
            return
        self.last_stamp = stamp
        position = conv.odometry_state(msg)[:2]
        t = stamp * 1e-9
        events = self.perception.step(position, t)
        for event, oid in events:
            self.get_logger().info(f't={t:.2f} s: obstacle {oid} {event.value}')
        for oid in sorted(self.perception.truth.held - self.held):
            self.get_logger().info(f't={t:.2f} s: obstacle {oid} held back: the robot is '
                                   'within its appear clearance')
        self.held = self.perception.truth.held
        if events:
            self.publish(stamp)
        self.publish_truth(stamp)
        in_range = len(self.existing_shapes.update(self.perception.truth.existing).within(
            position, self.perception.radius))
        self.status = PerceptionStatus(
            header=msg.header, detected_stamp=conv.time_msg(self.detected_stamp),
            known=len(self.perception.known_ids), in_range=in_range,
            detected=[oid for e, oid in events if e is ObstacleEvent.DETECTED],
            removed=[oid for e, oid in events if e is ObstacleEvent.REMOVED])
        self.status_pub.publish(self.status)

    def publish_truth(self, stamp: int) -> None:
        existing = [spec.id for spec in self.perception.truth.existing]
        if existing != self.existing:
            self.existing = existing
            self.truth_pub.publish(conv.obstacle_array_msg(
                stamp, [(oid, self.specs[oid].polygon) for oid in existing]))

    def publish(self, stamp: int) -> None:
        known = [(oid, self.specs[oid].polygon) for oid in self.specs
                 if oid in self.perception.known_ids]
        self.pub.publish(conv.obstacle_array_msg(stamp, known))
        self.detected_stamp = stamp


def main(args: list[str] | None = None) -> None:
    spin_node(SpawnerNode, args)


if __name__ == '__main__':
    main()
