"""Safety node: kinodynamic margin, augmented obstacles, clearance to the map (RRT-QX §2, §5).

Each step: D_rob of the robot from its current leg (from the controller's state of the
step before) and the margin of the scenario's ``safety.margin`` policy
(:mod:`rrtq_planner.margins`: the paper's running maximum by default, or a conformal or
learned bound, ``docs/margins.md``); when that margin has moved by the growth threshold, up
or down, or the detected set changed, every detected obstacle grown by margin + robot
radius is published on /obstacles/augmented (latched) so that the planner repairs its graph
(:meth:`rrtq_planner.safety.SafetyMonitor.step`). A leg whose deviation exceeds the margin
in force for it is logged and counted. The node also reports the clearance of the robot's
disc to the nearest detected obstacle and flags the step its odometry puts the disc onto
one; /safety/status goes out every step.

It stands on the robot's side: it reads /odom, the perception (/obstacles/detected,
/perception/status), /controller/state and its settings (the scenario's bounds and robot
radius among them), never the scenario file, whose obstacles are the truth. The true
clearance and collision are the referee's (/referee/status, :mod:`rrtq_sim.referee`).
"""

from __future__ import annotations

from typing import Any

from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import (ControllerState, DisturbanceEstimate, ObstacleArray, PerceptionStatus,
                           SafetyStatus)

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Requirement, Step, StepGate, seconds_to_ns
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import Dimensions, RunConfig
from rrtq_planner.conversions import (disturbance_estimate_msg, leg_of, margin_sample,
                                     safety_status_msg)
from rrtq_planner.margins.build import MarginConfig, make_policy
from rrtq_planner.margins.calibration import read_calibration
from rrtq_planner.margins.learned import LearnedBoundPolicy
from rrtq_planner.margins.policy import MarginMode
from rrtq_planner.safety import SafetyConfig, SafetyMonitor


class SafetyNode(Node):
    """Grows the detected obstacles by the margin policy's bound on the deviation."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('safety', **NODE_OPTIONS, **kwargs)
        run = declare_config(self, RunConfig, exclude=('seed',))
        self.dims = declare_config(self, Dimensions)
        config = declare_config(self, SafetyConfig)
        margins = declare_config(self, MarginConfig)
        calibration = read_calibration(margins.calibration) if margins.calibration else ()
        self.needs_gain = margins.margin is MarginMode.LEARNED_BOUND
        self.policy = make_policy(
            margins.margin, region=config.region, dt=run.dt,
            confidence=margins.confidence, window=margins.window,
            initial_margin=margins.initial_margin, calibration=calibration,
            frame=margins.frame, n=self.dims.n, m=self.dims.m,
            prior_bound=margins.prior_bound, robot_radius=config.robot_radius,
            conformal=margins.conformal)
        self.monitor = SafetyMonitor(config)
        self.aug_pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_AUGMENTED,
                                             qos.LATCHED)
        self.status_pub = self.create_publisher(SafetyStatus, topics.SAFETY_STATUS, qos.STREAM)
        # learned_bound only: its field and band at each fit (for the record and the report).
        self.estimate_pub = (self.create_publisher(DisturbanceEstimate,
                                                   topics.DISTURBANCE_ESTIMATE, qos.LATCHED)
                             if isinstance(self.policy, LearnedBoundPolicy) else None)
        self._fits = 0
        self.gate = StepGate(
            [Requirement('perception', followup='detected',
                         names=lambda m: conv.stamp_ns(m.detected_stamp)),
             Requirement('state', lag=1)],
            lockstep=run.lockstep, dt_ns=seconds_to_ns(run.dt), resend=self.status_pub.publish,
            on_step=self.step)
        subscribe_inputs(self, self.gate, (
            Input('odom', Odometry, topics.ODOM, qos.STREAM),
            Input('detected', ObstacleArray, topics.OBSTACLES_DETECTED, qos.LATCHED),
            Input('perception', PerceptionStatus, topics.PERCEPTION_STATUS, qos.STREAM),
            Input('state', ControllerState, topics.CONTROLLER_STATE, qos.STREAM)))

    def step(self, step: Step) -> None:
        odom, detected, state = step['odom'], step.get('detected'), step.get('state')
        x = conv.odometry_state(odom)
        margin = self.policy.step(margin_sample(step.stamp_ns * 1e-9, x, state, self.dims.n,
                                                self.dims.m, self.needs_gain))
        if margin.violation:
            self.get_logger().warning(
                f'leg {margin.legs}: deviation {margin.leg_deviation:.3f} m above the margin '
                f'{margin.leg_margin:.3f} m in force for it at t={step.stamp_ns * 1e-9:.2f} s '
                f'({margin.mode}; violation {margin.violations}): the margin is raised for '
                'the rest of the leg')
        if self.estimate_pub is not None and isinstance(self.policy, LearnedBoundPolicy) \
                and self.policy.fits != self._fits:
            self._fits = self.policy.fits
            est = self.policy.estimate()
            if est is not None:
                self.estimate_pub.publish(disturbance_estimate_msg(step.stamp_ns, est))
        done = self.monitor.step(step.stamp_ns, x[:2], conv.changed_obstacles(detected),
                                 leg_of(state), (margin.d_rob, margin.d_rob_max, margin.margin),
                                 margin.local, velocity=x[2:4])
        if done.augmented is not None:
            self.aug_pub.publish(conv.obstacle_array_msg(step.stamp_ns, done.augmented,
                                                         done.margin, done.local_margins))
        if done.new_collision:
            self.get_logger().error(f'the odometry puts the robot onto detected obstacle '
                                    f'{done.nearest} at t={step.stamp_ns * 1e-9:.2f} s, '
                                    f'({x[0]:.2f}, {x[1]:.2f})')
        status = safety_status_msg(odom.header, done, margin)
        self.gate.answered(step.stamp_ns, status)
        self.status_pub.publish(status)


def main(args: list[str] | None = None) -> None:
    spin_node(SafetyNode, args)


if __name__ == '__main__':
    main()
