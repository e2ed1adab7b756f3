"""Planner node: RRT^X on /goal_pose, /odom and /obstacles/augmented; /plan out.

The augmented set's ``margin`` also shrinks the scenario's bounds: the planner's nodes and
edges lie in the bounds shrunk by it (:class:`rrtq_planner.bounds.Region`).

With ``planner.guidance.mode: gvf`` it also runs the guiding level (VF-LPC §IV-A,
:class:`rrtq_planner.guidance.GuidanceSession`): the plan is the desired path, the
augmented obstacles the fields' obstacles, and every cycle's reference trajectory goes
out on /guidance/reference, stamped with the step, before the statistics.

Anytime (:class:`rrtq_planner.session.PlannerSession`): the graph keeps growing between
changes, within a budget per cycle — a fixed number of iterations per step in lock-step
mode, a slice of wall time per timer cycle in paced mode. The plan is republished
(latched) whenever its waypoints change; statistics go out every cycle and the tree,
throttled, for display.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from rrtq_msgs.msg import GuidanceReference, ObstacleArray, PlannerStats, SafetyStatus
from visualization_msgs.msg import MarkerArray

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Requirement, Step, StepGate, seconds_to_ns
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import RunConfig
from rrtq_planner.conversions import reference_msg, stats_msg, tree_bytes
from rrtq_planner.guidance import GuidanceConfig, GuidanceMode, GuidanceSession
from rrtq_planner.session import Budget, PlannerConfig, PlannerSession


class PlannerNode(Node):
    """RRT^X with the robot's position and the augmented obstacles."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('planner', **NODE_OPTIONS, **kwargs)
        self.run = declare_config(self, RunConfig)
        self.config = declare_config(self, PlannerConfig)
        self.session: PlannerSession | None = None
        # planner.guidance: the reference of the guiding vector field, every cycle (gvf).
        guidance = declare_config(self, GuidanceConfig, dt=self.run.dt)
        self.guidance = None
        if guidance.mode is GuidanceMode.GVF:
            self.guidance = GuidanceSession(guidance)
            self.reference_pub = self.create_publisher(
                GuidanceReference, topics.GUIDANCE_REFERENCE, qos.STREAM)
        self.plan_pub = self.create_publisher(Path, topics.PLAN, qos.LATCHED)
        self.stats_pub = self.create_publisher(PlannerStats, topics.PLANNER_STATS, qos.STREAM)
        self.tree_pub = self.create_publisher(MarkerArray, topics.PLANNER_TREE, qos.LATCHED)
        self.gate = StepGate(
            [Requirement('safety', followup='augmented',
                         names=lambda m: conv.stamp_ns(m.augmented_stamp))],
            lockstep=self.run.lockstep, dt_ns=seconds_to_ns(self.run.dt),
            resend=self._publish, on_step=self._on_step, held=True)
        self.create_subscription(PoseStamped, topics.GOAL_POSE, self.on_goal, qos.LATCHED)
        subscribe_inputs(self, self.gate, (
            Input('odom', Odometry, topics.ODOM, qos.STREAM),
            Input('augmented', ObstacleArray, topics.OBSTACLES_AUGMENTED, qos.LATCHED),
            Input('safety', SafetyStatus, topics.SAFETY_STATUS, qos.STREAM)))
        if not self.run.lockstep:
            self.create_timer(0.02, self.paced_cycle)

    def on_goal(self, msg: PoseStamped) -> None:
        goal = (msg.pose.position.x, msg.pose.position.y)
        if self.session is None or tuple(self.session.goal) != goal:
            self.session = PlannerSession(self.config.rrtx(goal),
                                          np.random.default_rng(self.run.seed), self.config)
            self.get_logger().info(f'goal ({goal[0]:.2f}, {goal[1]:.2f}): planning')
        self.gate.release()

    def _on_step(self, step: Step) -> None:
        """Lock-step: a cycle of the iteration budget per step (paced cycles run on a timer)."""
        if self.run.lockstep:
            self.cycle(step, Budget(iterations=self.config.iterations_per_step))

    def paced_cycle(self) -> None:
        """Paced: a cycle on the latest of every input, within a slice of wall time."""
        odom = self.gate.latest.get('odom')
        if self.session is not None and odom is not None:
            deadline = time.perf_counter() + self.config.cycle_budget_ms * 1e-3
            self.cycle(Step(conv.stamp_ns(odom.header.stamp), dict(self.gate.latest)),
                       Budget(deadline=deadline))

    def cycle(self, step: Step, budget: Budget) -> None:
        """Repair for obstacle changes, follow the robot, refine, publish."""
        assert self.session is not None
        augmented = step.get('augmented')
        done = self.session.cycle(step.stamp_ns, conv.odometry_state(step['odom'])[:2],
                                  conv.changed_obstacles(augmented), budget,
                                  None if augmented is None else augmented.margin)
        if done.changed:
            self.plan_pub.publish(conv.path_msg(step.stamp_ns, done.plan.waypoints))
        stats = stats_msg(done)
        reference = None
        if self.guidance is not None:
            odom = step['odom']
            out = self.guidance.cycle(step.stamp_ns * 1e-9, conv.odometry_state(odom),
                                      done.plan.waypoints, done.plan_stamp_ns,
                                      conv.changed_obstacles(step.get('augmented')))
            reference = reference_msg(step.stamp_ns, out, self.guidance.config.dt)
        self.gate.answered(step.stamp_ns, stats, reference)
        self._publish(stats, reference)
        if done.tree is not None:
            self.tree_pub.publish(tree_bytes(step.stamp_ns, done.tree))


    def _publish(self, stats: PlannerStats, reference: GuidanceReference | None = None) -> None:
        # The reference first: the controller's step waits for it, and is released by it.
        if reference is not None:
            self.reference_pub.publish(reference)
        self.stats_pub.publish(stats)


def main(args: list[str] | None = None) -> None:
    spin_node(PlannerNode, args)


if __name__ == '__main__':
    main()
