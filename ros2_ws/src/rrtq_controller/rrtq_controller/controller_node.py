"""Controller node: /odom and /plan in, /cmd_force and /controller/state out.

The learning variants also read /safety/status: the nearest detected obstacle and the one
ahead along the velocity, for the keep-off (:class:`rrtq_controller.guard.KeepOff`).

Variants: ``nominal`` and ``robust`` (model-free finite-horizon Q-learning, leg by leg
along the plan) and ``open_loop`` (a scripted force profile): a
:class:`rrtq_controller.driver.Driver` each. Every /odom step is answered with a
/controller/state and a /cmd_force stamped with the odometry's time.

In lock-step mode a step is processed only when its inputs are complete: the planner's
statistics of the same step, and the plan they name when it changed, and the safety
status of the same step (learning variants; the keep-off); the disturbance that acted
over the previous step (the robust variant learns the game from the measured
disturbance, the nominal one takes it into its critic's rows unless
``measured_disturbance`` is false); the guidance reference of the same step and the augmented obstacle set it
names (vf_lpc, which tracks the reference and puts its barrier on those obstacles). Paced
mode uses whatever arrived last.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from rrtq_msgs.msg import (ControllerState, Disturbance, GuidanceReference, ObstacleArray,
                           PlannerStats, SafetyStatus)

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import OnChange, Requirement, Step, StepGate, seconds_to_ns
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import Dimensions, RunConfig
from rrtq_controller.config import ControllerConfig, Variant
from rrtq_controller.conversions import changed_reference, command_msg, controller_state_msg
from rrtq_controller.driver import Watch
from rrtq_controller.drivers import make_driver
from rrtq_controller.vf_lpc import LPCConfig


def _keeps_off(config: ControllerConfig) -> bool:
    """Whether the controller reads /safety/status for the keep-off (guard.KeepOff)."""
    return config.variant in (Variant.NOMINAL, Variant.ROBUST) and config.keep_off > 0.0


Obstacle = tuple[float, np.ndarray] | None


def _obstacles(status: SafetyStatus | None) -> tuple[Obstacle, Obstacle]:
    """The nearest detected obstacle of a /safety/status and the one ahead along the velocity.

    Each is (distance m, unit vector); (None, None) when no status was received.
    """
    if status is None:
        return None, None
    near, ahead = status.obstacle_direction, status.ahead_direction
    return ((float(status.obstacle_distance), np.array([near.x, near.y])),
            (float(status.ahead_distance), np.array([ahead.x, ahead.y])))


def _requirements(config: ControllerConfig) -> list[Requirement]:
    """What a lock-step step waits for: the planner's word on it, the last disturbance (when read)."""
    needs = []
    if config.variant is not Variant.OPEN_LOOP:
        needs.append(Requirement('stats', followup='plan',
                                 names=lambda m: conv.stamp_ns(m.plan_stamp)))
    if config.reads_disturbance:
        needs.append(Requirement('disturbance', lag=1))
    if _keeps_off(config):
        needs.append(Requirement('safety'))
    if config.variant is Variant.VF_LPC:
        needs.append(Requirement('reference', followup='augmented',
                                 names=lambda m: conv.stamp_ns(m.obstacles_stamp)))
    return needs


class ControllerNode(Node):
    """Answers each odometry step with a force and the controller's state."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('controller', **NODE_OPTIONS, **kwargs)
        dims = declare_config(self, Dimensions)
        run = declare_config(self, RunConfig, exclude=('dt',))
        self.config = declare_config(self, ControllerConfig, dims)
        vf_lpc = self.config.variant is Variant.VF_LPC
        extra = ({'lpc': declare_config(self, LPCConfig, exclude=('force_limit',))}
                 if vf_lpc else {})
        self.driver = make_driver(self.config, dims.n, dims.m, dims.q,
                                  np.random.default_rng(run.seed), **extra)
        for warning in self.driver.warnings:
            self.get_logger().warning(warning)
        self.state_pub = self.create_publisher(ControllerState, topics.CONTROLLER_STATE,
                                               qos.STREAM)
        self.cmd_pub = self.create_publisher(WrenchStamped, topics.CMD_FORCE, qos.STREAM)
        self.gate = StepGate(_requirements(self.config), lockstep=run.lockstep,
                             dt_ns=seconds_to_ns(self.config.dt), resend=self._publish,
                             on_step=self.process)
        self.last_cmd: WrenchStamped | None = None
        subscribe_inputs(self, self.gate, (
            Input('odom', Odometry, topics.ODOM, qos.STREAM),
            Input('plan', Path, topics.PLAN, qos.LATCHED),
            Input('stats', PlannerStats, topics.PLANNER_STATS, qos.STREAM))
            # Only a controller that learns from it hears the injector's disturbance.
            + ((Input('disturbance', Disturbance, topics.DISTURBANCE, qos.STREAM),)
               if self.config.reads_disturbance else ())
            + ((Input('safety', SafetyStatus, topics.SAFETY_STATUS, qos.STREAM),)
               if _keeps_off(self.config) else ())
            + ((Input('reference', GuidanceReference, topics.GUIDANCE_REFERENCE, qos.STREAM),
                Input('augmented', ObstacleArray, topics.OBSTACLES_AUGMENTED, qos.LATCHED))
               if vf_lpc else ()))
        self._start_timers(run)

    def _start_timers(self, run: RunConfig) -> None:
        """Paced mode: the odometry watchdog (lock-step has no timer)."""
        if not run.lockstep:
            self.create_timer(0.05, self._watch_odometry)

    def _watch_odometry(self) -> None:
        watch = self.driver.watch(time.monotonic())
        if watch is Watch.WENT_STALE:
            self.get_logger().warning(f'no odometry for more than '
                                      f'{self.config.stale_timeout_s:g} s: commanding zero force')
        if watch is not Watch.FRESH and self.last_cmd is not None:
            self.cmd_pub.publish(WrenchStamped(header=self.last_cmd.header))

    def process(self, step: Step) -> None:
        if self.driver.odometry_arrived(time.monotonic()):
            self.get_logger().info('odometry is back: control resumes')
        wall = time.perf_counter()
        odom, plan, dist = step['odom'], step.get('plan'), step.get('disturbance')
        t = step.stamp_ns * 1e-9
        augmented = conv.changed_obstacles(step.get('augmented'))
        self.driver.set_odometry_variance(conv.odometry_variance(odom))
        out = self.driver.control(
            t, conv.odometry_state(odom), conv.changed_path(plan),
            None if dist is None else dist.value, changed_reference(step.get('reference')),
            None if augmented is None else OnChange(
                augmented.stamp_ns, lambda: [poly for _, poly in augmented.read()]),
            *_obstacles(step.get('safety')))
        if out is None:
            self.get_logger().error(f'non-finite odometry at t={t:.2f} s: commanding zero',
                                    throttle_duration_sec=1.0)
        state = controller_state_msg(odom.header.stamp, self.config, out)
        state.step_ms = (time.perf_counter() - wall) * 1e3
        cmd = command_msg(odom.header.stamp, state.command)
        self.gate.answered(step.stamp_ns, state, cmd)
        self._publish(state, cmd)

    def _publish(self, state: ControllerState, cmd: WrenchStamped) -> None:
        # State first: the simulator takes the spring anchor from it.
        self.last_cmd = cmd
        self.state_pub.publish(state)
        self.cmd_pub.publish(cmd)


def main(args: list[str] | None = None) -> None:
    spin_node(ControllerNode, args)


if __name__ == '__main__':
    main()
