"""Planner node: RRT^X on /goal_pose, /odom and /obstacles/augmented; /plan out.

Anytime: the graph keeps growing between changes, within a budget per cycle — a fixed
number of iterations per step in lock-step mode (so that a run repeats exactly), a
slice of wall time per timer cycle in paced mode (so the executor is never held for
long). The plan is republished (latched) whenever its waypoints change; statistics go
out every cycle and the tree, throttled, for display.
"""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import Point, PoseStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from rrtq_msgs.msg import ObstacleArray, PlannerStats, SafetyStatus
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from rrtq_planner.rrtx_config import PlanStatus, RRTXConfig
from rrtq_planner.session import Plan, PlannerSession
from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.lockstep import Requirement, StepInputs, seconds_to_ns
from rrtq_sim.params import declare, spin_node

STATUS = {PlanStatus.SEARCHING: PlannerStats.STATUS_SEARCHING, PlanStatus.FOUND:
          PlannerStats.STATUS_FOUND, PlanStatus.NO_PATH: PlannerStats.STATUS_NO_PATH}


class PlannerNode(Node):
    """RRT^X with the robot's position and the augmented obstacles."""

    def __init__(self, **kwargs) -> None:
        super().__init__('planner', **kwargs)
        d = lambda *a, **k: declare(self, *a, **k)  # noqa: E731
        self.bounds = tuple(d('bounds', [-20.0, 20.0, -20.0, 20.0],
                              'sampling region x_min x_max y_min y_max, m', element=float))
        self.steer = d('steer_distance', 5.0, 'RRT^X steer distance delta, m', low=1e-3)
        self.epsilon = d('epsilon', 0.0, 'RRT^X epsilon-consistency, m', low=0.0)
        self.seed = d('seed', 0, 'seed of the sampler', low=0)
        self.iterations = d('iterations_per_step', 30, 'lock-step: sampling iterations per '
                            'step', low=0)
        self.max_nodes = d('max_nodes', 3000, 'past this many nodes the graph only fills '
                           'gaps (space not covered yet, or freed by a vanished obstacle)',
                           low=2)
        self.budget_s = d('cycle_budget_ms', 10.0, 'paced: wall time of sampling per cycle, '
                          'ms', low=0.1) * 1e-3
        self.tree_period = d('tree_period_s', 1.0, 'sim time between /planner/tree messages, '
                             's', low=0.0)
        dt = d('dt', 0.05, 'step of the simulation, s (lock-step stamps)', low=1e-4)
        chain = d('chain', [''], "lock-step inputs awaited per step: 'safety_status' "
                  '(empty: paced)', element=str)
        self.lockstep = any(chain)
        self.inputs = StepInputs(
            [Requirement('safety', followup='augmented',
                         names=lambda m: conv.stamp_ns(m.augmented_stamp))]
            if 'safety_status' in chain else [], seconds_to_ns(dt))
        self.session: PlannerSession | None = None
        self.pending_obstacles: dict[str, np.ndarray] | None = None
        self.position: np.ndarray | None = None
        self.plan_stamp = 0
        self.last_repair_ms = 0.0
        self.last_tree_ns = -1
        self.now_ns = 0
        self.plan_pub = self.create_publisher(Path, topics.PLAN, qos.LATCHED)
        self.stats_pub = self.create_publisher(PlannerStats, topics.PLANNER_STATS, qos.STREAM)
        self.tree_pub = self.create_publisher(MarkerArray, topics.PLANNER_TREE, qos.LATCHED)
        self.last_stats: PlannerStats | None = None
        self.create_subscription(PoseStamped, topics.GOAL_POSE, self.on_goal, qos.LATCHED)
        self.create_subscription(Odometry, topics.ODOM, self._filer('odom'), qos.STREAM)
        self.create_subscription(ObstacleArray, topics.OBSTACLES_AUGMENTED,
                                 self._filer('augmented'), qos.LATCHED)
        self.create_subscription(SafetyStatus, topics.SAFETY_STATUS, self._filer('safety'),
                                 qos.STREAM)
        if not self.lockstep:
            self.create_timer(0.02, self.paced_cycle)

    # -- inputs ---------------------------------------------------------------------------
    def on_goal(self, msg: PoseStamped) -> None:
        goal = (msg.pose.position.x, msg.pose.position.y)
        if self.session is None or tuple(self.session.goal) != goal:
            config = RRTXConfig(goal=goal, bounds=self.bounds, steer_distance=self.steer,
                                epsilon=self.epsilon, max_nodes=self.max_nodes)
            self.session = PlannerSession(config, np.random.default_rng(self.seed))
            self.get_logger().info(f'goal ({goal[0]:.2f}, {goal[1]:.2f}): planning')
        self._run_ready_steps()

    def _filer(self, key: str):
        def callback(msg) -> None:
            stamp = conv.stamp_ns(msg.header.stamp)
            if key == 'odom' and self.last_stats is not None and self.lockstep \
                    and stamp <= conv.stamp_ns(self.last_stats.header.stamp):
                self.stats_pub.publish(self.last_stats)   # a resent step: answer again
                return
            if not self.lockstep:
                if key == 'odom':
                    self.position = conv.odometry_state(msg)[:2]
                    self.now_ns = stamp
                elif key == 'augmented':
                    self.pending_obstacles = dict(conv.obstacle_array(msg))
                return
            self.inputs.add(key, stamp, msg)
            self._run_ready_steps()
        return callback

    def _run_ready_steps(self) -> None:
        if self.session is None or not self.lockstep:
            return
        for step in self.inputs.pop_ready():
            augmented = step.get('augmented')
            self.cycle(step['stamp_ns'], conv.odometry_state(step['odom'])[:2],
                       None if augmented is None else dict(conv.obstacle_array(augmented)),
                       iterations=self.iterations)

    # -- cycles ---------------------------------------------------------------------------
    def paced_cycle(self) -> None:
        if self.session is None or self.position is None:
            return
        obstacles, self.pending_obstacles = self.pending_obstacles, None
        self.cycle(self.now_ns, self.position, obstacles, deadline=time.perf_counter()
                   + self.budget_s)

    def cycle(self, stamp: int, position: np.ndarray, obstacles: dict | None,
              iterations: int = 0, deadline: float | None = None) -> None:
        """Repair for obstacle changes, follow the robot, refine, publish."""
        session = self.session
        assert session is not None
        if obstacles is not None:
            start = time.perf_counter()
            if session.set_obstacles(obstacles):
                self.last_repair_ms = (time.perf_counter() - start) * 1e3
        session.set_robot(position)
        start = time.perf_counter()
        done = 0
        if deadline is None:
            done = iterations
            session.iterate(done)
        else:
            while time.perf_counter() < deadline:
                before = session.planner.node_count
                session.iterate(10)
                done += 10
                if before >= self.max_nodes and session.planner.node_count == before:
                    break   # full, and no gap found this time: leave the core to others
        cycle_ms = (time.perf_counter() - start) * 1e3
        plan = session.take_changed_plan()
        if plan is not None:
            self.plan_stamp = stamp
            self.plan_pub.publish(self._path_msg(stamp, plan))
        self._publish_stats(stamp, session.plan(), done, cycle_ms)
        if self.tree_period >= 0 and (self.last_tree_ns < 0 or stamp - self.last_tree_ns
                                      >= seconds_to_ns(self.tree_period)):
            self.last_tree_ns = stamp
            self.tree_pub.publish(self._tree_msg(stamp, session))

    # -- messages -------------------------------------------------------------------------
    def _path_msg(self, stamp: int, plan: Plan) -> Path:
        msg = Path()
        msg.header.stamp = conv.time_msg(stamp)
        msg.header.frame_id = conv.MAP_FRAME
        for x, y in plan.waypoints:
            pose = PoseStamped()
            pose.header = msg.header
            pose.pose.position.x, pose.pose.position.y = float(x), float(y)
            pose.pose.orientation.w = 1.0
            msg.poses.append(pose)
        return msg

    def _publish_stats(self, stamp: int, plan: Plan, iterations: int, cycle_ms: float) -> None:
        session = self.session
        assert session is not None
        stats = PlannerStats(
            status=STATUS[plan.status], nodes=session.planner.node_count,
            path_cost=float(plan.cost), replans=session.replans,
            last_repair_ms=self.last_repair_ms, iterations=iterations, cycle_ms=cycle_ms,
            ball_radius=float(session.planner.radius),
            plan_stamp=conv.time_msg(self.plan_stamp))
        stats.header.stamp = conv.time_msg(stamp)
        stats.header.frame_id = conv.MAP_FRAME
        self.last_stats = stats
        self.stats_pub.publish(stats)

    def _tree_msg(self, stamp: int, session: PlannerSession) -> MarkerArray:
        marker = Marker(ns='rrtx_tree', id=0, type=Marker.LINE_LIST, action=Marker.ADD)
        marker.header.stamp = conv.time_msg(stamp)
        marker.header.frame_id = conv.MAP_FRAME
        marker.pose.orientation.w = 1.0
        marker.scale.x = 0.03
        marker.color = ColorRGBA(r=0.6, g=0.6, b=0.6, a=0.8)
        marker.points = [Point(x=float(x), y=float(y)) for seg in session.tree_segments()
                         for x, y in seg]
        return MarkerArray(markers=[marker])


def main(args: list[str] | None = None) -> None:
    spin_node(PlannerNode, args)


if __name__ == '__main__':
    main()
