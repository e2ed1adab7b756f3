"""Controller node: /odom and /plan in, /cmd_force and /controller/state out.

Variants: ``nominal`` and ``robust`` (model-free finite-horizon Q-learning, leg by leg
along the plan) and ``open_loop`` (a scripted force profile). Every /odom step is
answered with a /controller/state and a /cmd_force stamped with the odometry's time.

In lock-step mode a step is processed only when its inputs are complete (``chain``):
the planner's statistics of the same step, and the plan they name when it changed;
the disturbance that acted over the previous step (robust variant, which learns the
game from the measured disturbance). Paced mode uses whatever arrived last.
"""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import Point, WrenchStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState, Disturbance, PlannerStats

from rrtq_controller.config import ActorLaw, ControllerConfig, CriticLaw, Variant
from rrtq_controller.driver import ControlOutput, LearningDriver, OpenLoopDriver
from rrtq_controller.open_loop import ForceProfile
from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.lockstep import Requirement, StepInputs, seconds_to_ns
from rrtq_sim.params import declare, spin_node

VARIANTS = ('nominal', 'robust', 'open_loop')


def _floats(values) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=float).ravel()]


class ControllerNode(Node):
    """Answers each odometry step with a force and the controller's state."""

    def __init__(self, **kwargs) -> None:
        super().__init__('controller', **kwargs)
        d = lambda *a, **k: declare(self, *a, **k)  # noqa: E731
        self.variant = d('variant', 'open_loop', 'controller variant: ' + ' | '.join(VARIANTS))
        if self.variant not in VARIANTS:
            raise ValueError(f'controller variant {self.variant!r} is not one of {VARIANTS}')
        n, m, q = (d('n', 4, 'state dimension', low=2), d('m', 2, 'input dimension', low=1),
                   d('q', 1, 'disturbance dimension', low=0))
        horizon = d('horizon', 10.0, 'leg horizon T, s', low=1e-3)
        dt = d('dt', 0.05, 'control step, s', low=1e-4)
        self.horizon = horizon
        self.rho = d('rho', 0.15, 'admissible window of the terminal-state evaluation',
                     low=1e-9, high=1.0)
        if self.variant == 'open_loop':
            self.driver = OpenLoopDriver(
                ForceProfile.from_rows(d('forces', [0.0, 0.0, 0.0], 'open_loop: flattened rows '
                                         '[t (s), fx (N), fy (N)]', element=float)),
                d('goal', [0.0, 0.0], 'open_loop: target (m), the goal', element=float), horizon)
        else:
            self.driver = LearningDriver(self._config(d, self.variant, n, m, horizon, dt,
                                                      self.rho), n, m, q,
                                         np.random.default_rng(d('seed', 0, 'probing seed',
                                                                 low=0)))
            for warning in self.driver.controller.warnings:
                self.get_logger().warning(warning)
        chain = d('chain', [''], 'lock-step inputs awaited per step: planner_stats, '
                  'disturbance (empty: answer each odometry at once)', element=str)
        self.lockstep = any(chain)
        requirements = []
        if 'planner_stats' in chain:
            requirements.append(Requirement('stats', followup='plan',
                                            names=lambda m: conv.stamp_ns(m.plan_stamp)))
        if 'disturbance' in chain:
            requirements.append(Requirement('disturbance', lag=1))
        self.inputs = StepInputs(requirements, seconds_to_ns(dt))
        self.plan_stamp = -1
        self.latest: dict[str, object] = {}
        self.last: tuple[int, ControllerState, WrenchStamped] | None = None
        self.state_pub = self.create_publisher(ControllerState, topics.CONTROLLER_STATE,
                                               qos.STREAM)
        self.cmd_pub = self.create_publisher(WrenchStamped, topics.CMD_FORCE, qos.STREAM)
        self.create_subscription(Odometry, topics.ODOM, self._filer('odom'), qos.STREAM)
        self.create_subscription(Path, topics.PLAN, self._filer('plan'), qos.LATCHED)
        self.create_subscription(PlannerStats, topics.PLANNER_STATS, self._filer('stats'),
                                 qos.STREAM)
        self.create_subscription(Disturbance, topics.DISTURBANCE, self._filer('disturbance'),
                                 qos.STREAM)
        self.stale_after = d('stale_timeout_s', 0.5, 'paced mode: wall time without odometry '
                             'after which the controller commands zero force, s', low=0.0)
        self.last_odom_wall: float | None = None
        self.stale = False
        if not self.lockstep:
            self.create_timer(0.05, self._watch_odometry)

    @staticmethod
    def _config(d, variant: str, n: int, m: int, horizon: float, dt: float,
                rho: float) -> ControllerConfig:
        def matrix(name: str, size: int, default: float) -> np.ndarray:
            flat = np.asarray(d(name, [default], f'{name}: scalar or row-major {size}x{size}',
                                element=float))
            return flat.reshape(size, size) if flat.size > 1 else float(flat[0]) * np.eye(size)

        optional = {}
        for name, doc in (('alpha_c', 'critic gain, 1/s'), ('alpha_a', 'actor gain, 1/s'),
                          ('alpha_d', 'disturbance-actor gain, 1/s'),
                          ('probing_std', 'probing std on the first leg, N'),
                          ('probing_decay', 'probing decay per leg')):
            value = d(name, -1.0, f'{doc} (< 0: the default)')
            if value >= 0.0:
                optional[name] = value
        gain = d('initial_gain', [0.0], 'initial actor gain K0 (m x n, row-major); '
                 'a single 0 means none', element=float)
        return ControllerConfig(
            horizon=horizon, dt=dt, M=matrix('M', n, 10.0), R=matrix('R', m, 2.0),
            P_T=matrix('P_T', n, 0.5),
            variant=Variant(variant),
            critic_law=CriticLaw(d('critic_law', 'least_squares', 'least_squares | gradient')),
            actor_law=ActorLaw(d('actor_law', 'whitened', 'whitened | gradient')),
            gamma=d('gamma', 3.0, 'attenuation level (robust)', low=1e-9),
            rho=rho,
            initial_gain=(None if len(gain) == 1 else
                          tuple(map(tuple, np.asarray(gain).reshape(m, n)))), **optional)

    # -- inputs -------------------------------------------------------------------------
    def _filer(self, key: str):
        def callback(msg) -> None:
            stamp = conv.stamp_ns(msg.header.stamp)
            if key == 'odom' and self.last is not None and stamp <= self.last[0]:
                self._publish(*self.last[1:])   # a resent step: answer it again, unchanged
                return
            if not self.lockstep:
                self.latest[key] = msg
                if key == 'odom':
                    self.last_odom_wall = time.monotonic()
                    if self.stale:
                        self.stale = False
                        self.get_logger().info('odometry is back: control resumes')
                    self.process(stamp, msg, self.latest.get('plan'),
                                 self.latest.get('disturbance'))
                return
            self.inputs.add(key, stamp, msg)
            for step in self.inputs.pop_ready():
                self.process(step['stamp_ns'], step['odom'], step.get('plan'),
                             step.get('disturbance'))
        return callback

    def _watch_odometry(self) -> None:
        """Paced mode: like Nav2's collision monitor on a timed-out source, stop pushing
        when the odometry has gone stale (the state the command was for is unknown)."""
        if self.last_odom_wall is None or self.last is None:
            return
        age = time.monotonic() - self.last_odom_wall
        if age <= self.stale_after:
            return
        if not self.stale:
            self.stale = True
            self.get_logger().warning(f'no odometry for {age:.2f} s (limit '
                                      f'{self.stale_after:g} s): commanding zero force')
        cmd = WrenchStamped()
        cmd.header = self.last[2].header
        self.cmd_pub.publish(cmd)

    # -- the step -----------------------------------------------------------------------
    def process(self, stamp: int, odom: Odometry, plan: Path | None,
                disturbance: Disturbance | None) -> None:
        wall = time.perf_counter()
        x = conv.odometry_state(odom)
        t = stamp * 1e-9
        if not np.all(np.isfinite(x)):
            self.get_logger().error(f'non-finite odometry at t={t:.2f} s: commanding zero',
                                    throttle_duration_sec=1.0)
            self._answer(stamp, odom, None, wall)
            return
        if plan is not None and conv.stamp_ns(plan.header.stamp) != self.plan_stamp:
            self.plan_stamp = conv.stamp_ns(plan.header.stamp)
            self.driver.set_plan([[p.pose.position.x, p.pose.position.y] for p in plan.poses],
                                 x, t)
        d_applied = None
        if disturbance is not None and np.all(np.isfinite(disturbance.value)):
            d_applied = np.asarray(disturbance.value, dtype=float)
        self._answer(stamp, odom, self.driver.step(t, x, d_applied), wall)

    def _answer(self, stamp: int, odom: Odometry, out: ControlOutput | None,
                wall: float) -> None:
        u = out.u if out is not None else np.zeros(2)
        state = ControllerState(variant=self.variant, command=_floats(u))
        if out is not None:
            state.leg_index = out.leg_index
            state.leg_start_time, state.horizon = out.leg_start_time, self.horizon
            state.time_to_go = out.time_to_go
            state.leg_start = Point(x=float(out.leg_start[0]), y=float(out.leg_start[1]))
            state.leg_target = Point(x=float(out.leg_target[0]), y=float(out.leg_target[1]))
            state.d0, state.d, state.rho = out.d0, out.d, self.rho
            state.probing_noise = _floats(out.probing)
            if isinstance(self.driver, LearningDriver):
                state.time_rates = _floats(self.driver.controller.time_basis.rates)
                state.time_powers = _floats(self.driver.controller.time_basis.powers)
            state.critic_weights = _floats(out.critic_weights)
            state.actor_weights = _floats(out.actor_weights)
            state.disturbance_weights = _floats(out.disturbance_weights)
            state.critic_error, state.terminal_error = out.critic_error, out.terminal_error
        state.header.stamp = odom.header.stamp
        state.header.frame_id = conv.MAP_FRAME
        state.step_ms = (time.perf_counter() - wall) * 1e3
        cmd = WrenchStamped()
        cmd.header.stamp = odom.header.stamp
        cmd.header.frame_id = conv.ROBOT_FRAME
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
