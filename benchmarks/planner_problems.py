"""Planning problems of the OMPL comparison and their exact optima.

BNeck and rand_Static are Otte's files (robot radius 0.5 m); the forests are the
seeded random polygon forests of the planner tests.  Obstacles are grown exactly
as ``rrtq plan`` grows them; the optimum is the shortest path in the visibility
graph of the polygons grown by R (the test helper ``visibility_optimum``, shapely +
networkx, independent of the planner).
"""

from __future__ import annotations

import importlib.util
import pathlib
import sys
from dataclasses import dataclass

import numpy as np

from rrtq_planner.plan_cli import default_bounds, grow

ROOT = pathlib.Path(__file__).resolve().parents[1]
TEST_DIR = ROOT / 'ros2_ws/src/rrtq_planner/test'
RADIUS = 0.5


def _load_helper():
    if 'visibility_optimum' in sys.modules:
        return sys.modules['visibility_optimum']
    spec = importlib.util.spec_from_file_location('visibility_optimum',
                                                  TEST_DIR / 'visibility_optimum.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules['visibility_optimum'] = module
    spec.loader.exec_module(module)
    return module


vo = _load_helper()


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
    data = TEST_DIR / 'data'
    out = [make_problem('BNeck', vo.read_otte(data / 'BNeck.txt'), (0, 40), (0, -40)),
           make_problem('rand_Static', vo.read_otte(data / 'rand_Static.txt'), (35, -40),
                        (-40, 40))]
    for seed in forest_seeds:
        polys, start, goal = vo.random_forest(seed)
        out.append(make_problem(f'forest{seed}', polys, start, goal))
    return out
