"""The shortest collision-free path among polygons: the optimum paths are judged by.

Independent of the planner (shapely and networkx only): the obstacles are grown by the
robot's radius (shapely's buffer, whose chords lie inside the exact Minkowski sum, so
the optimum is never overestimated), and the shortest path is Dijkstra's on the
visibility graph of the start, the goal and the convex corners of the grown obstacles'
union. A shortest path among polygons bends only at such corners.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Sequence

import networkx as nx
import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient

__all__ = ['Optimum', 'shortest_path']

# A segment that only grazes the union (along an edge, through a corner) is free: the
# visibility test is against the union shrunk by this much, m.
_GRAZE = 1e-7


@dataclasses.dataclass(frozen=True, eq=False)
class Optimum:
    """A shortest path.

    Attributes
    ----------
    length : float
        m; ``inf`` when the goal cannot be reached.
    path : numpy.ndarray, shape (k, 2)
        Waypoints from the start to the goal, m (empty when unreachable).
    """

    length: float
    path: np.ndarray

    @property
    def reachable(self) -> bool:
        """True when a path exists."""
        return math.isfinite(self.length)


def _corners(union: shapely.Geometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corners a shortest path may bend at, with their two ring neighbours.

    Those are the convex corners of the union's outer rings and every corner of its
    holes (enclosed free space).

    Returns
    -------
    (corners, previous, next), each of shape (k, 2)
    """
    out: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for part in getattr(union, 'geoms', [union]):
        if part.is_empty:
            continue
        ccw = orient(part, 1.0)
        rings = [(ccw.exterior, True)] + [(hole, False) for hole in ccw.interiors]
        for ring, outer in rings:
            pts = np.asarray(ring.coords)[:-1]
            prev, nxt = np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0)
            before, after = pts - prev, nxt - pts
            keep = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0] > 0.0
            if not outer:
                keep[:] = True
            out.append((pts[keep], prev[keep], nxt[keep]))
    if not out:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2))
    corners, prev, nxt = (np.concatenate(parts) for parts in zip(*out))
    return corners, prev, nxt


def _wraps(corner: np.ndarray, prev: np.ndarray, nxt: np.ndarray,
           direction: np.ndarray) -> np.ndarray:
    """True where the line through ``corner`` along ``direction`` leaves both neighbours on one side.

    That is the only way a shortest path passes a corner (NaN neighbours: an end
    point, always true).
    """
    side_prev = direction[:, 0] * (prev - corner)[:, 1] - direction[:, 1] * (prev - corner)[:, 0]
    side_next = direction[:, 0] * (nxt - corner)[:, 1] - direction[:, 1] * (nxt - corner)[:, 0]
    return ~(side_prev * side_next < -1e-12)


def shortest_path(polygons: Sequence[npt.ArrayLike], start: npt.ArrayLike,
                  goal: npt.ArrayLike, radius: float = 0.0,
                  bounds: tuple[tuple[float, float], tuple[float, float]] | None = None,
                  quad_segs: int = 8) -> Optimum:
    """Shortest path from ``start`` to ``goal`` for a disc of ``radius`` among ``polygons``.

    Parameters
    ----------
    polygons : sequence of array_like, shape (k, 2), or of shapely polygons
        Obstacles, m.
    start, goal : array_like, shape (2,)
        m.
    radius : float
        Robot radius, m: every obstacle is grown by it.
    bounds : ((x_min, x_max), (y_min, y_max)), optional
        The path's waypoints must lie inside (a box is convex: so do its segments).
    quad_segs : int
        Chords per quarter circle of the growth.

    Returns
    -------
    Optimum
    """
    a, b = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    shapes = [p if isinstance(p, shapely.Geometry) else Polygon(np.asarray(p, dtype=float))
              for p in polygons]
    if radius > 0.0:
        shapes = [s.buffer(radius, quad_segs=quad_segs) for s in shapes]
    union = shapely.union_all(shapes) if shapes else shapely.Polygon()
    corners, prev, nxt = _corners(union)
    ends = np.full((2, 2), np.nan)
    nodes, prev, nxt = (np.vstack(x) for x in ((a, b, corners), (ends, prev), (ends, nxt)))
    if bounds is not None:
        (x0, x1), (y0, y1) = bounds
        inside = (nodes[:, 0] >= x0) & (nodes[:, 0] <= x1) & (nodes[:, 1] >= y0) \
            & (nodes[:, 1] <= y1)
        inside[:2] = True
        nodes, prev, nxt = nodes[inside], prev[inside], nxt[inside]
    cores = [p for p in getattr(union.buffer(-_GRAZE), 'geoms', [union.buffer(-_GRAZE)])
             if not p.is_empty]
    if any(c.contains(shapely.Point(p)) for c in cores for p in (a, b)):
        return Optimum(math.inf, np.zeros((0, 2)))
    i, j = np.triu_indices(len(nodes), 1)
    d = nodes[j] - nodes[i]
    keep = _wraps(nodes[i], prev[i], nxt[i], d) & _wraps(nodes[j], prev[j], nxt[j], d)
    i, j, d = i[keep], j[keep], d[keep]
    free = np.ones(len(i), dtype=bool)
    if cores:
        segments = shapely.linestrings(np.stack((nodes[i], nodes[j]), axis=1))
        hit, _ = shapely.STRtree(cores).query(segments, predicate='intersects')
        free[hit] = False
    graph: nx.Graph[int] = nx.Graph()
    lengths = np.hypot(d[:, 0], d[:, 1])
    graph.add_weighted_edges_from(zip(i[free].tolist(), j[free].tolist(), lengths[free].tolist()))
    try:
        # With a target, the stubs' union is (length, path).
        length, route = typing.cast(tuple[float, list[int]],
                                    nx.single_source_dijkstra(graph, 0, 1))
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        return Optimum(math.inf, np.zeros((0, 2)))
    return Optimum(float(length), nodes[route])
