"""Exact shortest paths among grown polygons, random forests, Otte files: path ground truth.

Independent of the planner (shapely and networkx only), so tests and the OMPL benchmark
can judge path lengths against the true optimum: the shortest path in the visibility
graph of the grown polygons (:mod:`rrtq_common.optimum`, the one implementation).
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from rrtq_common.optimum import shortest_path as optimum
from rrtq_common.otte import read_polygons, write_otte

__all__ = ['OTTE', 'read_otte', 'write_otte', 'random_forest', 'grow', 'shortest_path',
           'clearance', 'length']

OTTE = pathlib.Path(__file__).parent / 'data' / 'otte'
"""Otte's environments ``BNeck.txt`` and ``rand_Static.txt`` (see the README there)."""

read_otte = read_polygons


def random_forest(seed: int, count: int = 30, half: float = 50.0,
                  radius: float = 0.5) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """A seeded forest of convex polygons in [-half, half]^2, with a start and a goal.

    Polygons: 3 to 7 vertices at random angles around a centre, 2 to 8 m across
    the centre; they may overlap.  Start and goal are drawn near opposite
    corners, at least 2 R clear of every polygon.
    """
    rng = np.random.default_rng(seed)
    polys = []
    for _ in range(count):
        c = rng.uniform(-half + 8.0, half - 8.0, 2)
        k = int(rng.integers(3, 8))
        ang = np.sort(rng.uniform(0.0, 2.0 * math.pi, k))
        rad = rng.uniform(2.0, 8.0) * rng.uniform(0.6, 1.0, k)
        poly = c + np.column_stack((rad * np.cos(ang), rad * np.sin(ang)))
        hull = shapely.convex_hull(shapely.multipoints(poly))
        if hull.geom_type == 'Polygon' and hull.area > 1.0:
            polys.append(np.asarray(hull.exterior.coords)[:-1])
    shapes = [Polygon(p) for p in polys]
    corner = rng.integers(0, 4)
    sx, sy = [(-1, -1), (1, -1), (1, 1), (-1, 1)][corner]
    while True:
        start = np.array([sx, sy]) * rng.uniform(0.75, 0.95, 2) * half
        goal = -np.array([sx, sy]) * rng.uniform(0.75, 0.95, 2) * half
        if all(s.distance(shapely.Point(p)) > 2 * radius for s in shapes for p in (start, goal)):
            return polys, start, goal


def grow(polygons: Sequence[np.ndarray], radius: float) -> list[Polygon]:
    """Polygons buffered by ``radius`` (shapely's chords lie inside the exact sum)."""
    return [Polygon(p).buffer(radius, quad_segs=16) if radius > 0 else Polygon(p)
            for p in polygons]


def shortest_path(grown: Sequence[Polygon], start: Sequence[float],
                  goal: Sequence[float]) -> tuple[float, np.ndarray]:
    """Shortest start -> goal path avoiding the interiors of ``grown``.

    Returns
    -------
    (length, waypoints); (inf, empty) when the goal is unreachable.
    """
    best = optimum(grown, start, goal)
    return best.length, best.path


def clearance(path: np.ndarray, polygons: Sequence[np.ndarray]) -> float:
    """Smallest distance (m) from the polyline to the original polygons (0 if touching)."""
    line = LineString(path) if len(path) > 1 else shapely.Point(path[0])
    return min(float(line.distance(Polygon(p))) for p in polygons)


def length(path: np.ndarray) -> float:
    """Length (m) of a polyline."""
    return float(np.sum(np.hypot(*np.diff(np.asarray(path), axis=0).T)))
