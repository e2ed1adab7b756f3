"""Test helper: exact shortest paths among grown polygons, random forests, Otte files.

Written independently of the planner (shapely + networkx only) so tests and the
OMPL benchmark can judge path lengths against the true optimum: the shortest
path in the visibility graph of the grown polygons.
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence

import networkx as nx
import numpy as np
import shapely
from shapely.geometry import LineString, Polygon


def read_otte(path: str | pathlib.Path) -> list[np.ndarray]:
    """Polygons of an Otte obstacle file (flag lines, if any, are skipped)."""
    rows = [r.strip() for r in pathlib.Path(path).read_text().splitlines() if r.strip()]
    polys, i = [], 1
    for _ in range(int(rows[0])):
        k = int(rows[i])
        poly = np.array([[float(v) for v in r.split(',')] for r in rows[i + 1:i + 1 + k]])
        if len(poly) > 3 and np.array_equal(poly[0], poly[-1]):
            poly = poly[:-1]
        polys.append(poly)
        i += 1 + k
        if i < len(rows) and rows[i] in ('0', '1', '-1'):
            i += 1
    return polys


def write_otte(path: str | pathlib.Path, polygons: Sequence[np.ndarray]) -> None:
    """Write polygons in Otte's format (closing vertex repeated, flag 0)."""
    lines = [str(len(polygons))]
    for poly in polygons:
        lines.append(str(len(poly) + 1))
        lines += [f'{x:.6f}, {y:.6f}' for x, y in np.vstack((poly, poly[:1]))]
        lines.append('0')
    pathlib.Path(path).write_text('\n'.join(lines) + '\n')


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

    Nodes: the end points and the convex vertices of the union's boundary.
    Edges: pairs whose segment is tangent at both polygon vertices (a shortest
    path only bends around a corner it wraps) and neither crosses nor runs
    inside the union.

    Returns
    -------
    (length, waypoints); (inf, empty) when the goal is unreachable.
    """
    union = shapely.union_all(grown)
    parts = list(getattr(union, 'geoms', [union]))
    nan = np.full(2, np.nan)
    nodes = [np.asarray(start, float), np.asarray(goal, float)]
    prev, nxt = [nan, nan], [nan, nan]
    for part in parts:
        outer = shapely.geometry.polygon.orient(part, 1.0)
        for ring, is_outer in [(outer.exterior, True)] + [(r, False) for r in outer.interiors]:
            pts = np.asarray(ring.coords)[:-1]
            a = np.roll(pts, 1, axis=0)
            b = np.roll(pts, -1, axis=0)
            turn = (pts[:, 0] - a[:, 0]) * (b[:, 1] - pts[:, 1]) \
                - (pts[:, 1] - a[:, 1]) * (b[:, 0] - pts[:, 0])
            # A reflex corner of an obstacle is never wrapped by a shortest path;
            # every corner of a hole (enclosed free space) is kept.
            sel = turn > 0 if is_outer else np.ones(len(pts), dtype=bool)
            nodes += list(pts[sel])
            prev += list(a[sel])
            nxt += list(b[sel])
    pts = np.array(nodes)
    prev_a = np.array(prev)
    next_a = np.array(nxt)
    n = len(pts)
    ii, jj = np.triu_indices(n, 1)
    d = pts[jj] - pts[ii]

    def tangent(at: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Both ring neighbours of the corner on one side of the segment's line."""
        pa = prev_a[at] - pts[at]
        pb = next_a[at] - pts[at]
        c1 = direction[:, 0] * pa[:, 1] - direction[:, 1] * pa[:, 0]
        c2 = direction[:, 0] * pb[:, 1] - direction[:, 1] * pb[:, 0]
        ok = c1 * c2 >= -1e-12
        return ok | np.isnan(pa[:, 0])

    keep = tangent(ii, d) & tangent(jj, -d)
    ii, jj = ii[keep], jj[keep]
    lines = shapely.linestrings(np.stack((pts[ii], pts[jj]), axis=1))
    tree = shapely.STRtree(parts)
    blocked = np.zeros(len(lines), dtype=bool)
    for predicate in ('crosses', 'within'):
        hit = tree.query(lines, predicate=predicate)
        blocked[hit[0]] = True
    graph = nx.Graph()
    for a, b in zip(ii[~blocked], jj[~blocked]):
        graph.add_edge(int(a), int(b), weight=float(np.hypot(*(pts[a] - pts[b]))))
    try:
        length, route = nx.single_source_dijkstra(graph, 0, 1, weight='weight')
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        return math.inf, np.zeros((0, 2))
    return float(length), pts[route]


def clearance(path: np.ndarray, polygons: Sequence[np.ndarray]) -> float:
    """Smallest distance (m) from the polyline to the original polygons (0 if touching)."""
    line = LineString(path) if len(path) > 1 else shapely.Point(path[0])
    return min(float(line.distance(Polygon(p))) for p in polygons)


def length(path: np.ndarray) -> float:
    """Length (m) of a polyline."""
    return float(np.sum(np.hypot(*np.diff(np.asarray(path), axis=0).T)))
