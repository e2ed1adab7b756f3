"""Obstacle mapper: the robot's obstacle map from its laser scans (``perception.source: scan``).

It stands on the robot's side: it reads /odom (where the robot believes it is) and /scan
(sensor_msgs/LaserScan in ``base_link``, axis-aligned with ``map`` for this heading-less
robot), places every scan in the map at the odometry's position of the scan's stamp, and
keeps the map with :class:`rrtq_planner.obstacle_map.ObstacleMap`. It then plays the part
the spawner plays with ``source: polygons``, in the same messages, so that the safety node
and the planner do not know the difference: /obstacles/detected (latched, the whole map,
whenever it changes) and, every step, /perception/status naming the stamp of the latest map.

Lock-step: a step waits for its odometry and, on the steps that carry one (every
``1 / (rate · dt)``-th), for its scan; the map of step 0 is always published.
"""

from __future__ import annotations

from typing import Any

from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ObstacleArray, PerceptionStatus
from sensor_msgs.msg import LaserScan

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Requirement, Step, StepGate, seconds_to_ns
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import RunConfig
from rrtq_common.scan import period_steps
from rrtq_planner.obstacle_map import MapEvent, MapperConfig, MapUpdate, ObstacleMap


class ObstacleMapperNode(Node):
    """Publishes the map built from the scans as the perception of the robot."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('obstacle_mapper', **NODE_OPTIONS, **kwargs)
        run = declare_config(self, RunConfig, exclude=('seed',))
        self.map = ObstacleMap(declare_config(self, MapperConfig))
        self.pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_DETECTED, qos.LATCHED)
        self.status_pub = self.create_publisher(PerceptionStatus, topics.PERCEPTION_STATUS,
                                                qos.STREAM)
        self.detected_stamp: int | None = None
        self.last_scan: int | None = None
        every = period_steps(self.map.config.rate, run.dt)
        self.gate = StepGate([Requirement('scan', every=every)], lockstep=run.lockstep,
                             dt_ns=seconds_to_ns(run.dt), resend=self.status_pub.publish,
                             on_step=self.step)
        subscribe_inputs(self, self.gate, (
            Input('odom', Odometry, topics.ODOM, qos.STREAM),
            Input('scan', LaserScan, topics.SCAN,
                  qos.STREAM if run.lockstep else qos.SENSOR_DATA)))

    def step(self, step: Step) -> None:
        scan = step.get('scan')
        update = MapUpdate([], 0)
        if scan is not None and conv.stamp_ns(scan.header.stamp) != self.last_scan:
            # Paced, a step carries the latest scan: each is integrated once.
            self.last_scan = conv.stamp_ns(scan.header.stamp)
            position = conv.odometry_state(step['odom'])[:2]
            update = self.map.integrate(position, conv.laser_scan_ranges(scan))
            self._log(step.stamp_ns * 1e-9, update)
        if update.events or self.detected_stamp is None:
            self.pub.publish(conv.obstacle_array_msg(
                step.stamp_ns, [(o.id, o.polygon) for o in self.map.obstacles]))
            self.detected_stamp = step.stamp_ns
        status = PerceptionStatus(
            header=step['odom'].header, detected_stamp=conv.time_msg(self.detected_stamp),
            known=len(self.map.obstacles), in_range=update.clusters,
            detected=[i for e, i in update.events if e is MapEvent.DETECTED],
            removed=[i for e, i in update.events if e is MapEvent.REMOVED])
        self.gate.answered(step.stamp_ns, status)
        self.status_pub.publish(status)

    def _log(self, t: float, update: MapUpdate) -> None:
        for event, ident in update.events:
            self.get_logger().info(f't={t:.2f} s: obstacle {ident} {event.value}')


def main(args: list[str] | None = None) -> None:
    spin_node(ObstacleMapperNode, args)


if __name__ == '__main__':
    main()
