"""Simulator node: owns /clock, steps the plant, publishes /odom every step.

Lock-step (``speed`` = 0, the CLI's ``--speed max``): step k+1 is taken only when every
topic in ``acks`` has delivered its message stamped with step k's time, so a run is a
function of its inputs alone. Paced (``speed`` > 0): a wall timer steps the plant at
``speed`` times real time with the latest inputs.
"""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Empty
from nav_msgs.msg import Odometry
from rrtq_msgs.msg import ControllerState, Disturbance, PerceptionStatus

from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.lockstep import StampJoin, seconds_to_ns
from rrtq_sim.params import declare, spin_node
from rrtq_sim.plant import Plant

ACK_TOPICS = {'cmd_force': (topics.CMD_FORCE, WrenchStamped),
              'controller_state': (topics.CONTROLLER_STATE, ControllerState),
              'disturbance': (topics.DISTURBANCE, Disturbance),
              'perception_status': (topics.PERCEPTION_STATUS, PerceptionStatus)}


def _matrix(flat: list[float], rows: int, name: str) -> np.ndarray:
    if rows <= 0 or len(flat) % rows:
        raise ValueError(f'parameter {name}: {len(flat)} values do not fill {rows} rows')
    return np.asarray(flat, dtype=float).reshape(rows, -1)


class SimulatorNode(Node):
    """The plant, its clock and its odometry."""

    def __init__(self, **kwargs) -> None:
        super().__init__('simulator', **kwargs)
        d = lambda *a, **k: declare(self, *a, **k)  # noqa: E731
        n = d('n', 4, 'plant state dimension', low=2)
        dt = d('dt', 0.05, 'plant step, s', low=1e-4)
        a = _matrix(d('A', [0.0], 'plant matrix A, row-major (n x n)', element=float), n, 'A')
        b = _matrix(d('B', [0.0], 'input matrix B, row-major (n x m)', element=float), n, 'B')
        f = _matrix(d('F', [0.0] * n, 'disturbance matrix F, row-major (n x q)',
                      element=float), n, 'F')
        self.plant = Plant(a, b, f, dt, d('force_limit', 1000.0, 'saturation, N per axis',
                                          low=1e-6))
        self.anchor_mode = d('spring_anchor', 'leg_target', 'leg_target | world_origin')
        start = d('start', [0.0, 0.0], 'initial position (m); the robot starts at rest')
        self.speed = d('speed', 0.0, '0 = lock-step as fast as possible; > 0 = wall-clock '
                       'pace factor', low=0.0)
        self.acks = d('acks', ['cmd_force'], 'stamped outputs awaited before each '
                      'lock-step step: ' + ' '.join(ACK_TOPICS), element=str)
        self.duration_ns = seconds_to_ns(d('duration', 0.0, 'stop stepping at this sim '
                                           'time, s (0 = never)', low=0.0))
        self.wait_for = d('wait_for', [''], 'topic:count pairs; the first step waits until '
                          'each topic has that many subscribers', element=str)
        self.settle_s = d('settle_s', 0.5, 'wall time to wait once the graph is connected, so '
                          'that discovery between the other nodes completes too, s', low=0.0)
        self.resend_s = d('resend_period_s', 2.0, 'lock-step: republish the current odometry '
                          'if acknowledgements stall this long (wall), s', low=0.01)

        self.dt_ns = seconds_to_ns(dt)
        self.step_index = 0
        self.x = np.zeros(self.plant.n)
        self.x[:2] = start
        self.anchor = np.array(start[:2], dtype=float)
        self.u = np.zeros(self.plant.m)
        self.d = np.zeros(self.plant.q)
        self.rejected_inputs = 0
        self.started = False
        self.wall_start: float | None = None
        self._last_publish = time.monotonic()

        self.clock_pub = self.create_publisher(Clock, topics.CLOCK, qos.CLOCK)
        self.odom_pub = self.create_publisher(Odometry, topics.ODOM, qos.STREAM)
        self.join = StampJoin(self.acks)
        for key in sorted(set(self.acks) | {'cmd_force', 'controller_state', 'disturbance'}):
            topic, mtype = ACK_TOPICS[key]
            self.create_subscription(mtype, topic, self._input_callback(key), qos.STREAM)
        self.paused = False
        self.create_subscription(Empty, topics.SIMULATOR_PAUSE, self._pause, qos.LATCHED)
        self._ready_since: float | None = None
        self._gate = self.create_timer(0.02, self._try_start)

    # -- inputs ---------------------------------------------------------------
    def _input_callback(self, key: str):
        def callback(msg) -> None:
            if self.speed > 0.0:
                self._take_input(key, msg)
            elif key in self.join.keys:
                done = self.join.add(key, conv.stamp_ns(msg.header.stamp), msg)
                if done is not None and self.join.last_completed_ns == self.now_ns:
                    for k, m in sorted(done.items()):
                        self._take_input(k, m)
                    self.advance()
        return callback

    def _take_input(self, key: str, msg) -> None:
        if key == 'cmd_force':
            u = np.array([msg.wrench.force.x, msg.wrench.force.y])
            if np.all(np.isfinite(u)):
                self.u = u
            else:
                self._reject('cmd_force', u)
        elif key == 'disturbance':
            d = np.asarray(msg.value, dtype=float)
            if d.shape == self.d.shape and np.all(np.isfinite(d)):
                self.d = d
            else:
                self._reject('disturbance', d)
        elif key == 'controller_state' and self.anchor_mode == 'leg_target':
            self.anchor = np.array([msg.leg_target.x, msg.leg_target.y])

    def _reject(self, what: str, value: np.ndarray) -> None:
        """Never let a non-finite or misshapen input into the plant: hold zero instead."""
        self.rejected_inputs += 1
        self.get_logger().warning(f'rejected {what} {value.tolist()}: applying zero',
                                  throttle_duration_sec=1.0)
        if what == 'cmd_force':
            self.u = np.zeros(self.plant.m)
        else:
            self.d = np.zeros(self.plant.q)

    # -- stepping -------------------------------------------------------------
    @property
    def now_ns(self) -> int:
        return self.step_index * self.dt_ns

    def _graph_ready(self) -> bool:
        for item in self.wait_for:
            if not item:
                continue
            topic, _, count = item.rpartition(':')
            # Own publishers: readers actually matched to them (the graph's counts can run
            # ahead of endpoint matching). Other topics: what discovery reports.
            own = {topics.ODOM: self.odom_pub, topics.CLOCK: self.clock_pub}.get(topic)
            seen = own.get_subscription_count() if own else self.count_subscribers(topic)
            if seen < int(count):
                return False
        return all(self.count_publishers(ACK_TOPICS[key][0]) >= 1 for key in self.acks)

    def _try_start(self) -> None:
        if not self._graph_ready():
            self._ready_since = None
            return
        now = time.monotonic()
        if self._ready_since is None:
            self._ready_since = now
        if now - self._ready_since < self.settle_s:
            return
        self._gate.cancel()
        self.started = True
        self.wall_start = time.monotonic()
        self.publish_state()
        if self.speed > 0.0:
            self.create_timer(self.dt_ns * 1e-9 / self.speed, self.advance)
        else:
            self.create_timer(self.resend_s, self._resend_if_stalled)

    def _pause(self, _msg: Empty) -> None:
        """The mission is over: stop stepping, but stay up so that every reader can
        still take (and have resent) the last steps."""
        self.paused = True

    def advance(self) -> None:
        """One exact zero-order-hold step with the held force and disturbance."""
        if self.paused or (self.duration_ns and self.now_ns >= self.duration_ns):
            return
        anchor = self.anchor if self.anchor_mode == 'leg_target' else np.zeros(2)
        self.x = self.plant.step(self.x, self.u, self.d, anchor)
        self.step_index += 1
        self.publish_state()

    def publish_state(self) -> None:
        self.clock_pub.publish(conv.clock_msg(self.now_ns))
        self.odom_pub.publish(conv.odometry_msg(self.now_ns, self.x))
        self._last_publish = time.monotonic()

    def _resend_if_stalled(self) -> None:
        if self.duration_ns and self.now_ns >= self.duration_ns:
            return
        if time.monotonic() - self._last_publish >= self.resend_s:
            missing = ', '.join(sorted(self.join.missing(self.now_ns)))
            self.get_logger().warning(
                f'step {self.step_index}: no acknowledgement from {missing} for '
                f'{self.resend_s:.1f} s; republishing odometry')
            self.odom_pub.publish(conv.odometry_msg(self.now_ns, self.x))
            self._last_publish = time.monotonic()


def main(args: list[str] | None = None) -> None:
    spin_node(SimulatorNode, args)


if __name__ == '__main__':
    main()
