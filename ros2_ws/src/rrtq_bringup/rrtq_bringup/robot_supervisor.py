"""The supervisor of ``rrtq robot``: the mission judged from /odom on the mission's time."""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rrtq_msgs.msg import PlannerStats

from rrtq_bringup.mission import MissionClock, MissionMonitor
from rrtq_bringup.supervisor import SupervisorNode
from rrtq_common import conversions as conv
from rrtq_common import topics


class RobotSupervisorNode(SupervisorNode):
    """Publishes the goal; feeds the monitor from /odom, the clock from its arrivals."""

    def __init__(self, monitor: MissionMonitor, goal: np.ndarray, clock: MissionClock,
                 **kwargs) -> None:
        self.clock = clock
        super().__init__(monitor, goal, odometry=topics.ODOM, **kwargs)

    def on_odom(self, msg: conv.OdometryReading) -> None:  # type: ignore[override]
        stamp = conv.stamp_ns(msg.header.stamp)
        if stamp <= self.last_odom_ns:
            return
        self.last_odom_ns = stamp
        t = self.clock.odometry(stamp * 1e-9, time.monotonic())
        self.monitor.on_odometry(t, conv.odometry_state(msg)[:2])

    def on_cmd(self, msg: WrenchStamped) -> None:
        self.monitor.on_command(self.clock.time_of(conv.stamp_ns(msg.header.stamp) * 1e-9),
                                np.array([msg.wrench.force.x, msg.wrench.force.y]))

    def on_stats(self, msg: PlannerStats) -> None:
        self.monitor.on_plan_status(self.clock.time_of(conv.stamp_ns(msg.header.stamp) * 1e-9),
                                    msg.status == PlannerStats.STATUS_FOUND)
        if msg.replans > self.monitor.replans:
            self.monitor.replans = msg.replans
            self.monitor.replan_ms.append(msg.last_repair_ms)
