"""Planning problems of the OMPL comparison and their exact optima.

BNeck and rand_Static are Otte's files (robot radius 0.5 m); the forests are the
seeded random polygon forests of the planner tests.  Obstacles are grown exactly
as ``rrtq plan`` grows them; the optimum is the shortest path in the visibility
graph of the polygons grown by R (:mod:`rrtq_testing.paths`, shapely + networkx,
independent of the planner).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrtq_planner.routes import default_bounds, grow
from rrtq_testing import paths as vo

RADIUS = 0.5


@dataclass(frozen=True)
class Problem:
    """One query: original and grown polygons, end points, bounds, exact optimum."""

    name: str
    polygons: tuple[np.ndarray, ...]
    grown: tuple[np.ndarray, ...]
    start: np.ndarray
    goal: np.ndarray
    bounds: tuple[float, float, float, float]
    optimum: float


def make_problem(name: str, polygons: list[np.ndarray], start, goal,
                 radius: float = RADIUS) -> Problem:
    """Grow, bound and solve exactly."""
    start = np.asarray(start, dtype=float)
    goal = np.asarray(goal, dtype=float)
    optimum, _ = vo.shortest_path(vo.grow(polygons, radius), start, goal)
    return Problem(name, tuple(polygons), tuple(grow(polygons, radius)), start, goal,
                   default_bounds(polygons, start, goal, radius), float(optimum))


def problems(forest_seeds: list[int]) -> list[Problem]:
    """BNeck, rand_Static and the given forests."""
    data = vo.OTTE
    out = [make_problem('BNeck', vo.read_otte(data / 'BNeck.txt'), (0, 40), (0, -40)),
           make_problem('rand_Static', vo.read_otte(data / 'rand_Static.txt'), (35, -40),
                        (-40, 40))]
    for seed in forest_seeds:
        polys, start, goal = vo.random_forest(seed)
        out.append(make_problem(f'forest{seed}', polys, start, goal))
    return out
