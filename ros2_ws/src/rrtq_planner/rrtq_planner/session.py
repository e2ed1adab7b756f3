"""The planner as the node and the CLI use it: obstacle sets in, plans out (no rclpy).

Wraps :class:`rrtq_planner.rrtx.RRTX` with what both callers need: the obstacle set
given whole (as /obstacles/augmented carries it) turned into the additions and
removals RRT^X repairs for; the plan as waypoints from the robot's next waypoint to
the goal, and whether it changed since the last time it was taken.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from .rrtx import RRTX
from .rrtx_config import PlanStatus, RRTXConfig


@dataclasses.dataclass(frozen=True)
class Plan:
    """Waypoints (K, 2) m from the robot's next waypoint to the goal; empty if no path."""

    waypoints: np.ndarray
    cost: float                      # m, from the robot's position; inf without a path
    status: PlanStatus


class PlannerSession:
    """One goal, a changing obstacle set, a moving robot."""

    def __init__(self, config: RRTXConfig, rng: np.random.Generator) -> None:
        self.planner = RRTX(config, rng)
        self._obstacles: dict[str, np.ndarray] = {}
        self._last_waypoints: np.ndarray | None = None
        self.replans = 0

    @property
    def goal(self) -> np.ndarray:
        return np.asarray(self.planner.config.goal, dtype=float)

    def set_obstacles(self, obstacles: Mapping[str, np.ndarray]) -> bool:
        """Make the planner's obstacle set equal to ``obstacles`` (id -> polygon).

        Only the differences are repaired: ids that went away are removed, new ids and
        ids whose polygon changed (grown by a larger margin, say) are (re)added.
        Returns True when anything changed (a replan).
        """
        removed = [oid for oid in self._obstacles if oid not in obstacles]
        changed = {oid: np.asarray(poly, dtype=float) for oid, poly in obstacles.items()
                   if oid not in self._obstacles
                   or not np.array_equal(self._obstacles[oid], poly)}
        if not removed and not changed:
            return False
        self.planner.update_obstacles(added=changed, removed=removed)
        for oid in removed:
            del self._obstacles[oid]
        self._obstacles.update(changed)
        self.replans += 1
        return True

    def set_robot(self, position: np.ndarray) -> None:
        self.planner.set_robot(np.asarray(position, dtype=float)[:2])

    def iterate(self, iterations: int) -> None:
        """Anytime refinement: ``iterations`` sampling iterations of RRT^X."""
        self.planner.run(iterations)

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
