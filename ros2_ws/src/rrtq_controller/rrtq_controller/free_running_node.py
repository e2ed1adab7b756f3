"""The controller on its own Δt timer, against whatever publishes /odom (``rrtq robot``).

The lock-step and paced controller (:mod:`rrtq_controller.controller_node`) answers each
odometry message; this one steps on a timer of period Δt on the node's clock (sim time
when the run has a /clock, else wall time) with the newest odometry, as a controller on a
robot does. A tick that finds no newer odometry than the one it took before takes the next
as it arrives (on sim time the tick of step k comes with /clock, just before the plant's
odometry of step k). The age of the odometry is watched on a steady wall timer too
(:class:`rrtq_controller.staleness.OdometryWatch`), so that a plant that vanishes with its
/clock is noticed: odometry older than ``stale_steps`` Δt makes the controller command zero,
with ``policy_event`` ``stale_odometry`` in its /controller/state and a warning in its log,
and the first fresh odometry resumes control (``odometry_resumed``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.clock import Clock, ClockType
from rrtq_msgs.msg import ControllerState

from rrtq_common.lockstep import Step
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import RunConfig
from rrtq_controller.controller_node import ControllerNode
from rrtq_controller.conversions import command_msg, controller_state_msg
from rrtq_controller.staleness import (RESUMED_EVENT, STALE_EVENT, FreeRunConfig, Freshness,
                                       OdometryWatch)


class FreeRunningControllerNode(ControllerNode):
    """Steps every Δt with the newest odometry; zero force while it is stale."""

    def __init__(self, **kwargs: Any) -> None:
        self.newest: Step | None = None
        self.taken_ns = -1
        self.waiting = False
        self.event = ''
        super().__init__(**kwargs)

    def _start_timers(self, run: RunConfig) -> None:
        if run.lockstep:
            raise ValueError('the free-running controller runs paced (lockstep: false)')
        self.free = declare_config(self, FreeRunConfig)
        self.watch = OdometryWatch(self.config.dt, self.free.stale_steps)
        self.gate.on_step = self._take
        self.create_timer(self.config.dt, self._tick)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(self.free.watch_period_s, self._look, clock=self._steady)

    def _take(self, step: Step) -> None:
        """Keep the newest odometry (and the latest of every other input) for the next tick.

        A tick that found no newer odometry than the one it took before waits for the next:
        that one is taken as it arrives.
        """
        if not self.watch.arrived(step.stamp_ns * 1e-9, time.monotonic()):
            return
        self.newest = step
        if self.waiting:
            self.waiting = False
            self._control(self.newest)

    def _tick(self) -> None:
        if self._act(self.watch.check(time.monotonic()), tick=True):
            assert self.newest is not None
            if self.newest.stamp_ns > self.taken_ns:
                self._control(self.newest)
            else:
                self.waiting = True

    def _control(self, step: Step) -> None:
        self.taken_ns = step.stamp_ns
        self.process(step)

    def _look(self) -> None:
        self._act(self.watch.check(time.monotonic()), tick=False)

    def _act(self, fresh: Freshness, tick: bool) -> bool:
        """Say what changed and command zero when stale; True when a tick may control."""
        if fresh is Freshness.WENT_STALE:
            age, pace = self.watch.age(time.monotonic()), self.watch.pace
            reason = (f'odometry {age:.3f} s old (run time; {age / pace:.3f} s of wall time at '
                      f'pace {pace:.2f}), more than {self.free.stale_steps:g} dt = '
                      f'{self.watch.limit:.3f} s: commanding zero')
            self.get_logger().warning(f'{STALE_EVENT}: {reason}')
            self.waiting = False
            self._command_zero(STALE_EVENT, reason)
        elif fresh is Freshness.STALE and tick:
            self.waiting = False
            self._command_zero('', '')
        elif fresh is Freshness.RESUMED:
            self.get_logger().info(f'{RESUMED_EVENT}: control resumes')
            self.event = RESUMED_EVENT
        return tick and fresh in (Freshness.FRESH, Freshness.RESUMED)

    def _command_zero(self, event: str, reason: str) -> None:
        stamp = self.get_clock().now().to_msg()
        state = controller_state_msg(stamp, self.config, None)
        state.policy_event, state.policy_reason = event, reason
        self._publish(state, command_msg(stamp, np.zeros(2)))

    def _publish(self, state: ControllerState, cmd: WrenchStamped) -> None:
        if self.event:
            state.policy_event = ';'.join(e for e in (self.event, state.policy_event) if e)
            self.event = ''
        super()._publish(state, cmd)


def main(args: list[str] | None = None) -> None:
    spin_node(FreeRunningControllerNode, args)


if __name__ == '__main__':
    main()
