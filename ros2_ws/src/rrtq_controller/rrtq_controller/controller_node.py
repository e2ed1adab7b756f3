"""Controller node: /odom and /plan in, /cmd_force and /controller/state out.

This version carries the ``open_loop`` variant (a scripted force profile). Every
/odom step is answered with a /controller/state and a /cmd_force stamped with the
odometry's time: in lock-step mode the simulator waits for them.
"""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import Point, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState

from rrtq_controller.open_loop import ForceProfile
from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.params import declare, spin_node

VARIANTS = ('open_loop',)


class ControllerNode(Node):
    """Answers each odometry step with a force and the controller's state."""

    def __init__(self, **kwargs) -> None:
        super().__init__('controller', **kwargs)
        d = lambda *a, **k: declare(self, *a, **k)  # noqa: E731
        self.variant = d('variant', 'open_loop', 'controller variant: ' + ' | '.join(VARIANTS))
        if self.variant not in VARIANTS:
            raise ValueError(f'controller variant {self.variant!r} is not implemented; '
                             f'available: {", ".join(VARIANTS)}')
        self.profile = ForceProfile.from_rows(
            d('forces', [0.0, 0.0, 0.0], 'open_loop: flattened rows [t (s), fx (N), fy (N)]',
              element=float))
        self.target = np.array(d('goal', [0.0, 0.0], 'leg target (m): the goal', element=float))
        self.horizon = d('horizon', 10.0, 'leg horizon T, s', low=1e-3)
        self.force_frame = conv.ROBOT_FRAME
        self.state_pub = self.create_publisher(ControllerState, topics.CONTROLLER_STATE,
                                               qos.STREAM)
        self.cmd_pub = self.create_publisher(WrenchStamped, topics.CMD_FORCE, qos.STREAM)
        self.x0bar: np.ndarray | None = None
        self.leg_start = np.zeros(2)
        self.last: tuple[int, ControllerState, WrenchStamped] | None = None
        self.create_subscription(Odometry, topics.ODOM, self.on_odom, qos.STREAM)

    def on_odom(self, msg: Odometry) -> None:
        stamp = conv.stamp_ns(msg.header.stamp)
        if self.last is not None and stamp <= self.last[0]:
            self._publish(*self.last[1:])   # a resent step: answer it again, unchanged
            return
        wall = time.perf_counter()
        x = conv.odometry_state(msg)
        xbar = x - np.concatenate([self.target, np.zeros(x.size - 2)])
        if self.x0bar is None:
            self.x0bar, self.leg_start = xbar, x[:2].copy()
        t = stamp * 1e-9
        u = self.profile.force_at(t)
        state = ControllerState(
            variant=self.variant, leg_index=0, leg_start_time=0.0, horizon=self.horizon,
            time_to_go=max(0.0, self.horizon - t),
            leg_start=Point(x=float(self.leg_start[0]), y=float(self.leg_start[1])),
            leg_target=Point(x=float(self.target[0]), y=float(self.target[1])),
            d0=float(np.linalg.norm(self.x0bar)), d=float(np.linalg.norm(xbar)),
            command=[float(v) for v in u], probing_noise=[0.0] * u.size,
            step_ms=(time.perf_counter() - wall) * 1e3)
        state.header.stamp = msg.header.stamp
        state.header.frame_id = conv.MAP_FRAME
        cmd = WrenchStamped()
        cmd.header.stamp = msg.header.stamp
        cmd.header.frame_id = self.force_frame
        cmd.wrench.force.x, cmd.wrench.force.y = float(u[0]), float(u[1])
        self.last = (stamp, state, cmd)
        self._publish(state, cmd)

    def _publish(self, state: ControllerState, cmd: WrenchStamped) -> None:
        # State first: the simulator takes the spring anchor from it.
        self.state_pub.publish(state)
        self.cmd_pub.publish(cmd)


def main(args: list[str] | None = None) -> None:
    spin_node(ControllerNode, args)


if __name__ == '__main__':
    main()
