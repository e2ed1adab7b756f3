"""Obstacle spawner: the true world's obstacles, and what the robot perceives of them.

On every /odom step the perception core compares truth with the robot's map inside
the perception disc; whenever the map changes, the whole known set is published on
/obstacles/detected (latched, so late joiners get the current map).
"""

from __future__ import annotations

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ObstacleArray

from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.params import declare, spin_node
from rrtq_sim.perception import Perception
from rrtq_sim.scenario import load_scenario


class SpawnerNode(Node):
    """Publishes the known obstacle set at start and on every perception event."""

    def __init__(self, **kwargs) -> None:
        super().__init__('obstacle_spawner', **kwargs)
        scenario = load_scenario(declare(self, 'scenario', '', 'scenario YAML with the '
                                         'obstacles (validated by the orchestrator)'))
        self.specs = {spec.id: spec for spec in scenario.obstacles}
        self.perception = Perception(scenario.obstacles, scenario.perception_radius)
        self.pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_DETECTED, qos.LATCHED)
        self.last_stamp = -1
        self.create_subscription(Odometry, topics.ODOM, self.on_odom, qos.STREAM)
        self.publish(0)

    def on_odom(self, msg: Odometry) -> None:
        stamp = conv.stamp_ns(msg.header.stamp)
        if stamp <= self.last_stamp:
            return
        self.last_stamp = stamp
        events = self.perception.step(conv.odometry_state(msg)[:2], stamp * 1e-9)
        for event, oid in events:
            self.get_logger().info(f't={stamp * 1e-9:.2f} s: obstacle {oid} {event.value}')
        if events:
            self.publish(stamp)

    def publish(self, stamp: int) -> None:
        known = [(oid, self.specs[oid].polygon) for oid in self.specs
                 if oid in self.perception.known_ids]
        self.pub.publish(conv.obstacle_array_msg(stamp, known))


def main(args: list[str] | None = None) -> None:
    spin_node(SpawnerNode, args)


if __name__ == '__main__':
    main()
