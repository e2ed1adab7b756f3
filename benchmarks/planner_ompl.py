"""OMPL (the ``ompl`` wheel) on the same problems, with the same exact collision test.

A plain set-up of the wheel: OMPL's default planner parameters, a path-length
objective with cost threshold 0 (keep improving), a Python state validity
checker and a motion validator that makes one exact segment test per motion.
Both ask the planner's own ``ObstacleMap`` (the prepared GEOS union of the
closed, grown polygons), so OMPL never misses a collision between states and
pays one C call per check behind its Python callback, as RRT^X pays one per
vectorised batch.  (Until 2026-12 the motion validator ran the numpy edge test
polygon by polygon, ~30x the cost of a GEOS call; see
``results/planner_vs_ompl.md``.)
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from rrtq_planner.geometry import ObstacleMap

PLANNERS = {'RRTstar': og.RRTstar, 'InformedRRTstar': og.InformedRRTstar,
            'BITstar': og.BITstar}

if hasattr(ou, 'setLogLevel'):
    ou.setLogLevel(ou.LogLevel.LOG_ERROR)
# One seed for the process, before any planner draws (OMPL allows no reseeding).
ou.RNG.setSeed(1)


class _Validity(ob.StateValidityChecker):
    def __init__(self, si: ob.SpaceInformation, obstacles: ObstacleMap) -> None:
        super().__init__(si)
        self._obstacles = obstacles

    def isValid(self, state) -> bool:  # noqa: N802 - OMPL's name
        return self._obstacles.point_free((state[0], state[1]))


class _Motion(ob.MotionValidator):
    def __init__(self, si: ob.SpaceInformation, obstacles: ObstacleMap) -> None:
        super().__init__(si)
        self._obstacles = obstacles

    def checkMotion(self, s1, s2, *rest) -> bool:  # noqa: N802 - OMPL's name
        # The closed segment test covers both end states.
        p = np.array(((s1[0], s1[1]),))
        q = np.array(((s2[0], s2[1]),))
        return bool(self._obstacles.segments_free(p, q)[0])


class OmplQuery:
    """One problem set up for OMPL: space, checkers, start/goal, path-length objective."""

    def __init__(self, grown: Sequence[np.ndarray], start: np.ndarray, goal: np.ndarray,
                 bounds: tuple[float, float, float, float]) -> None:
        self.obstacles = ObstacleMap()
        for i, poly in enumerate(grown):
            self.obstacles.add(str(i), poly)
        self.space = ob.RealVectorStateSpace(2)
        b = ob.RealVectorBounds(2)
        b.setLow(0, bounds[0])
        b.setHigh(0, bounds[1])
        b.setLow(1, bounds[2])
        b.setHigh(1, bounds[3])
        self.space.setBounds(b)
        self.si = ob.SpaceInformation(self.space)
        self._validity = _Validity(self.si, self.obstacles)
        self._motion = _Motion(self.si, self.obstacles)
        self.si.setStateValidityChecker(self._validity)
        self.si.setMotionValidator(self._motion)
        self.si.setup()
        self._start = self.space.allocState()
        self._goal = self.space.allocState()
        self._start[0], self._start[1] = float(start[0]), float(start[1])
        self._goal[0], self._goal[1] = float(goal[0]), float(goal[1])
        self._keep: list[object] = []

    def new_problem(self, threshold: float | None = None) -> ob.ProblemDefinition:
        """A fresh problem definition (path length; optionally stop at ``threshold`` m)."""
        pdef = ob.ProblemDefinition(self.si)
        pdef.setStartAndGoalStates(self._start, self._goal)
        objective = ob.PathLengthOptimizationObjective(self.si)
        objective.setCostThreshold(ob.Cost(threshold if threshold is not None else 0.0))
        pdef.setOptimizationObjective(objective)
        self._keep += [pdef, objective]  # the bindings do not own them
        return pdef

    def planner(self, name: str, pdef: ob.ProblemDefinition):
        """A set-up planner of class ``name``."""
        planner = PLANNERS[name](self.si)
        planner.setProblemDefinition(pdef)
        planner.setup()
        self._keep.append(planner)
        return planner

    @staticmethod
    def cost(pdef: ob.ProblemDefinition) -> float:
        """Length (m) of the best exact solution so far, inf without one."""
        if not pdef.hasExactSolution():
            return float('inf')
        return float(pdef.getSolutionPath().length())

    def simplified_cost(self, pdef: ob.ProblemDefinition,
                        budget_s: float) -> tuple[float, float]:
        """Length of the simplified solution and the time simplifying took (s).

        A copy of the solution goes through ``PathSimplifier.simplify`` with a time limit
        of ``budget_s`` seconds.

        Like RRT^X's post-processing, which always shortens the tree path, it makes
        at least one pass even past the limit (``atLeastOnce``).
        """
        if not pdef.hasExactSolution():
            return float('inf'), 0.0
        path = og.PathGeometric(pdef.getSolutionPath())
        simplifier = og.PathSimplifier(self.si)
        t0 = time.perf_counter()
        simplifier.simplify(path, budget_s, True)
        elapsed = time.perf_counter() - t0
        return float(path.length()), elapsed

    def anytime(self, name: str, reads: Sequence[float],
                shorten: dict[float, float]) -> list[dict]:
        """Run one planner, reading the cost after each of ``reads`` s of solve time.

        At a read time t in ``shorten`` a copy of the solution is also simplified
        for ``shorten[t]`` seconds (the planner is paused meanwhile).
        """
        pdef = self.new_problem()
        planner = self.planner(name, pdef)
        spent = 0.0
        out = []
        for t in reads:
            while spent < t - 1e-4:
                t0 = time.perf_counter()
                planner.solve(t - spent)
                spent += time.perf_counter() - t0
            row = {'t': t, 'cost': self.cost(pdef)}
            if t in shorten:
                row['simplified'], row['simplify_s'] = self.simplified_cost(pdef, shorten[t])
            out.append(row)
        return out

    def time_to_cost(self, name: str, target: float, cap_s: float) -> dict:
        """Wall time (s) from scratch until a solution of length <= ``target`` m (cap_s)."""
        pdef = self.new_problem(threshold=target)
        planner = self.planner(name, pdef)
        t0 = time.perf_counter()
        first = None
        while time.perf_counter() - t0 < cap_s:
            planner.solve(min(0.05, cap_s - (time.perf_counter() - t0)) if first is None
                          else cap_s - (time.perf_counter() - t0))
            if first is None and pdef.hasExactSolution():
                first = time.perf_counter() - t0
            if self.cost(pdef) <= target:
                break
        elapsed = time.perf_counter() - t0
        reached = self.cost(pdef) <= target
        return {'reached': reached, 'time_s': elapsed if reached else None,
                'first_s': first, 'cost': self.cost(pdef)}
