"""The planner as the node runs it: obstacle sets in, plans out, within a budget (no rclpy).

Wraps :class:`rrtq_planner.rrtx.RRTX` with what the node needs: the obstacle set given
whole (as /obstacles/augmented carries it) turned into the additions and removals RRT^X
repairs for; the robot followed; the anytime refinement within a budget per cycle — a
fixed number of iterations per step in lock-step mode (so that a run repeats exactly),
a slice of wall time in paced mode (so the executor is never held for long); the plan
as waypoints from the robot's next waypoint to the goal, and whether it changed; the
tree for display, throttled.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable, Mapping

import numpy as np

from rrtq_common.lockstep import OnChange, seconds_to_ns
from rrtq_common.settings import check, like, setting

from .rrtx import RRTX
from .rrtx_config import PlanStatus, RRTXConfig

__all__ = ['PlannerConfig', 'Plan', 'Budget', 'Cycle', 'PlannerSession']


@dataclasses.dataclass(frozen=True, kw_only=True)
class PlannerConfig:
    """The planner node's settings: RRT^X's, and the anytime budget per cycle."""

    bounds: tuple[float, float, float, float] = like(RRTXConfig, 'bounds')
    steer_distance: float = like(RRTXConfig, 'steer_distance')
    epsilon: float = like(RRTXConfig, 'epsilon')
    stall_time: float = like(RRTXConfig, 'stall_time')
    max_nodes: int = setting(3000, low=2, doc='past this many nodes the graph only fills '
                             'gaps (space not covered yet, or freed by a vanished obstacle)')
    iterations_per_step: int = setting(30, low=0, doc='lock-step: sampling iterations per step')
    cycle_budget_ms: float = setting(10.0, unit='ms', low=0.1,
                                     doc='paced: wall time of sampling per cycle')
    tree_period_s: float = setting(1.0, unit='s', low=0.0,
                                   doc='sim time between /planner/tree messages')

    def __post_init__(self) -> None:
        check(self)

    def rrtx(self, goal: tuple[float, float]) -> RRTXConfig:
        """RRT^X's configuration for ``goal`` (m)."""
        return RRTXConfig(goal=goal, bounds=self.bounds, steer_distance=self.steer_distance,
                          epsilon=self.epsilon, max_nodes=self.max_nodes,
                          stall_time=self.stall_time)


@dataclasses.dataclass(frozen=True)
class Plan:
    """Waypoints (K, 2) m from the robot's next waypoint to the goal; empty if no path."""

    waypoints: np.ndarray
    cost: float                      # m, from the robot's position; inf without a path
    status: PlanStatus


@dataclasses.dataclass(frozen=True)
class Budget:
    """How much refinement one cycle may do.

    ``iterations`` (lock-step), or sampling in chunks until the clock passes
    ``deadline`` (paced).
    """

    iterations: int = 0
    deadline: float | None = None


@dataclasses.dataclass(frozen=True)
class Cycle:
    """What one cycle did and what the node publishes about it."""

    stamp_ns: int
    plan: Plan
    changed: bool                    # the waypoints differ from the last plan published
    plan_stamp_ns: int               # stamp of the latest plan published
    iterations: int
    cycle_ms: float                  # wall time of the refinement
    repair_ms: float                 # wall time of the latest obstacle repair
    nodes: int
    replans: int
    ball_radius: float               # m, r(n)
    tree: np.ndarray | None          # (E, 2, 2) m when the tree is due for display


class PlannerSession:
    """One goal, a changing obstacle set, a moving robot.

    Parameters
    ----------
    config : RRTXConfig
    rng : numpy.random.Generator
        The sampler's source.
    settings : PlannerConfig, optional
        The budget and the display period (default: the node's defaults for ``config``).
    clock : callable
        Wall clock, s (measures repairs and cycles; bounds paced cycles).
    """

    CHUNK = 10
    """Paced: iterations between two looks at the clock."""

    def __init__(self, config: RRTXConfig, rng: np.random.Generator,
                 settings: PlannerConfig | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.planner = RRTX(config, rng)
        self.settings = settings or PlannerConfig(bounds=config.bounds)
        self._clock = clock
        self._obstacles: dict[str, np.ndarray] = {}
        self._obstacles_stamp: int | None = None
        self._last_waypoints: np.ndarray | None = None
        self.replans = 0
        self._repair_ms = 0.0
        self._plan_stamp = 0
        self._tree_ns = -1

    @property
    def goal(self) -> np.ndarray:
        return np.asarray(self.planner.config.goal, dtype=float)

    def set_obstacles(self, obstacles: Mapping[str, np.ndarray],
                      margin: float | None = None) -> bool:
        """Make the planner's obstacle set equal to ``obstacles`` (id -> polygon).

        Only the differences are repaired: ids that went away are removed, new ids and
        ids whose polygon changed (grown by a larger margin, say) are (re)added. A
        ``margin`` (m, what the set was grown by) shrinks the bounds by as much: the
        planner's region (:class:`rrtq_planner.bounds.Region`). Returns True when
        anything changed (a replan).
        """
        removed = [oid for oid in self._obstacles if oid not in obstacles]
        changed = {oid: np.asarray(poly, dtype=float) for oid, poly in obstacles.items()
                   if oid not in self._obstacles
                   or not np.array_equal(self._obstacles[oid], poly)}
        if margin == self.planner.region.margin:
            margin = None
        if not removed and not changed and margin is None:
            return False
        self.planner.update_obstacles(added=changed, removed=removed, margin=margin)
        for oid in removed:
            del self._obstacles[oid]
        self._obstacles.update(changed)
        self.replans += 1
        return True

    def set_robot(self, position: np.ndarray, t: float | None = None) -> None:
        """Follow the robot (position m, at time ``t`` s: the stall rule of RRTXConfig)."""
        self.planner.set_robot(np.asarray(position, dtype=float)[:2], t)

    def iterate(self, iterations: int) -> None:
        """Anytime refinement: ``iterations`` sampling iterations of RRT^X."""
        self.planner.run(iterations)

    def refine(self, budget: Budget) -> int:
        """Refine within ``budget``; the number of iterations done.

        Paced, a full graph (``max_nodes``) that found no gap in a chunk stops early: the
        core is left to the other nodes.
        """
        if budget.deadline is None:
            self.iterate(budget.iterations)
            return budget.iterations
        done = 0
        while self._clock() < budget.deadline:
            before = self.planner.node_count
            self.iterate(self.CHUNK)
            done += self.CHUNK
            if before >= self.settings.max_nodes and self.planner.node_count == before:
                break
        return done

    def cycle(self, stamp_ns: int, position: np.ndarray,
              obstacles: OnChange[Iterable[tuple[str, np.ndarray]]] | None,
              budget: Budget, margin: float | None = None) -> Cycle:
        """Repair for an obstacle set that changed, follow the robot, refine, take the plan.

        ``margin`` (m): what that set was grown by, the bounds' shrink (None: unchanged).
        """
        if obstacles is not None and obstacles.stamp_ns != self._obstacles_stamp:
            self._obstacles_stamp = obstacles.stamp_ns
            start = self._clock()
            if self.set_obstacles(dict(obstacles.read()), margin):
                self._repair_ms = (self._clock() - start) * 1e3
        self.set_robot(position, stamp_ns * 1e-9)
        start = self._clock()
        done = self.refine(budget)
        cycle_ms = (self._clock() - start) * 1e3
        plan = self.take_changed_plan()
        if plan is not None:
            self._plan_stamp = stamp_ns
        tree = None
        if self.settings.tree_period_s >= 0 and (
                self._tree_ns < 0 or stamp_ns - self._tree_ns
                >= seconds_to_ns(self.settings.tree_period_s)):
            self._tree_ns = stamp_ns
            tree = self.tree_segments()
        return Cycle(stamp_ns=stamp_ns, plan=plan or self.plan(), changed=plan is not None,
                     plan_stamp_ns=self._plan_stamp, iterations=done, cycle_ms=cycle_ms,
                     repair_ms=self._repair_ms, nodes=self.planner.node_count,
                     replans=self.replans, ball_radius=float(self.planner.radius), tree=tree)

    def plan(self) -> Plan:
        """The current plan; the robot's own position is not a waypoint."""
        path = self.planner.path()
        robot = self.planner.robot
        if len(path) and robot is not None and np.array_equal(path[0], robot) and len(path) > 1:
            path = path[1:]
        return Plan(waypoints=path, cost=self.planner.cost(), status=self.planner.status)

    def take_changed_plan(self) -> Plan | None:
        """The plan if its waypoints differ from those last taken, else None."""
        plan = self.plan()
        if (self._last_waypoints is not None
                and np.array_equal(plan.waypoints, self._last_waypoints)):
            return None
        self._last_waypoints = plan.waypoints.copy()
        return plan

    def tree_segments(self) -> np.ndarray:
        """Parent edges of the tree as (E, 2, 2) segments (m), for display."""
        parents = self.planner.parents
        pos = self.planner.positions
        child = np.flatnonzero(parents >= 0)
        return np.stack([pos[child], pos[parents[child]]], axis=1)
