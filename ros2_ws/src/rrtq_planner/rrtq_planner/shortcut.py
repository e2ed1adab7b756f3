"""Path post-processing: visibility shortcuts and taut-string tightening (no rclpy).

A sampling planner's path zig-zags between its samples.  Two steps shorten it
without ever lengthening it or letting it touch an obstacle (obstacles are
closed sets, as in :mod:`rrtq_planner.geometry`):

* ``shortcut_vertices``: from each kept waypoint jump to the farthest later
  waypoint it sees (the greedy form of OMPL's ``PathSimplifier::reduceVertices``).
* ``tighten``: slide every bend onto the obstacle corners it wraps.  For a bend
  c between a and b whose chord ab is blocked, the obstacles that block ab lie
  inside the triangle (a, c, b) (they cannot cross the free sides ac and cb),
  so the shortest path from a to b homotopic to a-c-b is the convex hull chain
  of a, b and the obstacle corners inside the triangle.  Corners are taken
  pushed outward by ``push`` so the chain misses the closed polygons.

Alternating the two converges to the locally shortest (taut) path of the
homotopy class the planner found: at the fixed point every bend sits on an
obstacle corner and no corner lies inside any bend's triangle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .geometry import ObstacleMap, points_in_polygon, segments_cross_edges

__all__ = ['ShortcutConfig', 'Shortener', 'EdgeSet', 'path_length', 'outward_corners',
           'shortcut_vertices', 'tighten', 'simplify']


@dataclass(frozen=True)
class ShortcutConfig:
    """Parameters of :func:`simplify`.

    Attributes
    ----------
    rounds : int
        Maximum number of shortcut + tighten sweeps.
    push : float
        m; how far a waypoint placed at an obstacle corner is moved outward
        along the corner's bisector, so the path never touches the polygon.
    tolerance : float
        m; sweeps stop once one shortens the path by less than this.
    """

    rounds: int = 30
    push: float = 1e-6
    tolerance: float = 1e-9

    def __post_init__(self) -> None:
        if self.rounds < 0:
            raise ValueError('rounds must be >= 0')
        if not self.push > 0.0:
            raise ValueError('push must be > 0')
        if self.tolerance < 0.0:
            raise ValueError('tolerance must be >= 0')


def path_length(path: np.ndarray) -> float:
    """Length (m) of a polyline given as (k, 2) waypoints."""
    if len(path) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))


def outward_corners(polygons: Sequence[np.ndarray], push: float) -> np.ndarray:
    """Convex corners of the polygons, pushed outward by ``push`` (m), shape (m, 2).

    Only convex corners can carry a bend of a shortest path.  A pushed corner
    that falls inside another polygon (overlapping obstacles) is dropped: it
    is not on the boundary of the obstacle union.
    """
    out = []
    for poly in polygons:
        p = np.asarray(poly, dtype=float)
        area2 = float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1)))
        if area2 < 0.0:
            p = p[::-1]
        prev = np.roll(p, 1, axis=0)
        nxt = np.roll(p, -1, axis=0)
        e_in = p - prev
        e_out = nxt - p
        turn = e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0]
        # Outward normals of a counter-clockwise polygon's edges: (dy, -dx).
        n_in = np.column_stack((e_in[:, 1], -e_in[:, 0]))
        n_out = np.column_stack((e_out[:, 1], -e_out[:, 0]))
        n_in /= np.linalg.norm(n_in, axis=1, keepdims=True) + 1e-300
        n_out /= np.linalg.norm(n_out, axis=1, keepdims=True) + 1e-300
        bis = n_in + n_out
        norm = np.linalg.norm(bis, axis=1)
        keep = (turn > 0.0) & (norm > 1e-12)
        out.append(p[keep] + push * bis[keep] / norm[keep, None])
    if not out:
        return np.zeros((0, 2))
    corners = np.concatenate(out)
    inside = np.zeros(len(corners), dtype=bool)
    for poly in polygons:
        p = np.asarray(poly, dtype=float)
        box = np.flatnonzero(np.all((corners >= p.min(axis=0)) & (corners <= p.max(axis=0)),
                                    axis=1))
        if box.shape[0]:
            inside[box] |= points_in_polygon(corners[box], p)
    return np.asarray(corners[~inside])


class EdgeSet:
    """All polygon edges in flat arrays, for segments whose end points are free.

    A segment between two points outside every closed polygon meets a polygon
    exactly when it touches one of its edges, so no containment test is needed.
    """

    def __init__(self, polygons: Sequence[np.ndarray]) -> None:
        polys = [np.asarray(p, dtype=float) for p in polygons]
        if polys:
            self.a = np.concatenate(polys)
            self.b = np.concatenate([np.roll(p, -1, axis=0) for p in polys])
        else:
            self.a = np.zeros((0, 2))
            self.b = np.zeros((0, 2))
        self.lo = np.minimum(self.a, self.b)
        self.hi = np.maximum(self.a, self.b)

    def segments_free(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Which segments ``p[i]q[i]`` (free end points, (k, 2) each) miss every edge."""
        k = p.shape[0]
        if k == 0 or self.a.shape[0] == 0:
            return np.ones(k, dtype=bool)
        lo = np.minimum(p, q).min(axis=0)
        hi = np.maximum(p, q).max(axis=0)
        near = np.flatnonzero((self.lo[:, 0] <= hi[0]) & (self.hi[:, 0] >= lo[0])
                              & (self.lo[:, 1] <= hi[1]) & (self.hi[:, 1] >= lo[1]))
        if near.shape[0] == 0:
            return np.ones(k, dtype=bool)
        hit = segments_cross_edges(p, q, self.a[near], self.b[near])
        return np.asarray(~hit.any(axis=1))

    def free_from(self, start: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Which segments from ``start`` to each of ``ends`` (free points) miss every edge."""
        return self.segments_free(np.broadcast_to(start, ends.shape), ends)


def shortcut_vertices(path: np.ndarray, edges: EdgeSet) -> np.ndarray:
    """Greedy visibility shortcut: from each kept waypoint, the farthest visible one.

    Parameters
    ----------
    path : numpy.ndarray
        Collision-free waypoints (k, 2), m.
    edges : EdgeSet
        Edges of the (grown) obstacles.

    Returns
    -------
    numpy.ndarray
        A subsequence of ``path`` with the same end points; never longer.
    """
    if len(path) < 3:
        return path.copy()
    keep = [0]
    i = 0
    last = len(path) - 1
    while i < last:
        free = edges.free_from(path[i], path[i + 1:])
        seen = np.flatnonzero(free)
        # path[i] -> path[i + 1] is an edge of the path, free by assumption.
        j = i + 1 + (int(seen[-1]) if seen.shape[0] else 0)
        keep.append(j)
        i = j
    return np.asarray(path[keep])


def _hull_chain(a: np.ndarray, c: np.ndarray, b: np.ndarray,
                corners: np.ndarray) -> np.ndarray | None:
    """Shortest a -> b around the corners inside triangle (a, c, b): the hull chain.

    Returns the chain's interior points (possibly none), or None when the
    triangle is degenerate.
    """
    ab = b - a
    length = float(np.hypot(*ab))
    if length == 0.0:
        return None
    u = ab / length
    v = np.array([-u[1], u[0]])
    yc = float((c - a) @ v)
    if abs(yc) < 1e-12:
        return None
    if yc < 0.0:
        v = -v
        yc = -yc
    xc = float((c - a) @ u)
    rel = corners - a
    x = rel @ u
    y = rel @ v
    # Inside the closed triangle (0, 0), (xc, yc), (length, 0), strictly above ab.
    cand = (y > 0.0) & (y <= yc)
    cand &= x * yc - y * xc >= -1e-12 * length * yc       # right of a -> c
    cand &= (x - length) * yc - y * (xc - length) <= 1e-12 * length * yc  # left of b -> c
    if not cand.any():
        return np.zeros((0, 2))
    pts = np.column_stack((x[cand], y[cand]))
    order = np.lexsort((pts[:, 1], pts[:, 0]))
    pts = pts[order]
    # Upper hull is not enough (c may project outside [0, length]): build the
    # whole hull with a and b, counter-clockwise, then read b -> ... -> a.
    allp = np.vstack(([0.0, 0.0], [length, 0.0], pts))
    hull = _convex_hull(allp)
    ia = hull.index(0)
    ib = hull.index(1)
    chain = []
    k = ib
    while k != ia:
        k = (k + 1) % len(hull)
        if k != ia:
            chain.append(hull[k])
    chain.reverse()
    local = allp[chain]
    return np.asarray(a + local[:, 0:1] * u + local[:, 1:2] * v)


def _convex_hull(points: np.ndarray) -> list[int]:
    """Andrew's monotone chain; counter-clockwise indices, collinear points dropped."""
    idx = sorted(range(len(points)), key=lambda i: (points[i, 0], points[i, 1]))

    def cross(o: int, p: int, q: int) -> float:
        return float((points[p, 0] - points[o, 0]) * (points[q, 1] - points[o, 1])
                     - (points[p, 1] - points[o, 1]) * (points[q, 0] - points[o, 0]))

    lower: list[int] = []
    for i in idx:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], i) <= 0.0:
            lower.pop()
        lower.append(i)
    upper: list[int] = []
    for i in reversed(idx):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], i) <= 0.0:
            upper.pop()
        upper.append(i)
    return lower[:-1] + upper[:-1]


def tighten(path: np.ndarray, edges: EdgeSet, corners: np.ndarray) -> np.ndarray:
    """One sweep of corner sliding: replace each bend by its triangle's hull chain.

    A replacement is kept only when its segments are free and it is shorter,
    so the result is never longer than ``path`` and never collides.

    Parameters
    ----------
    path : numpy.ndarray
        Collision-free waypoints (k, 2), m.
    edges : EdgeSet
        Edges of the (grown) obstacles.
    corners : numpy.ndarray
        Candidate bend points, from :func:`outward_corners` (free points).
    """
    pts = [np.asarray(p, dtype=float) for p in path]
    i = 1
    while i < len(pts) - 1:
        a, c, b = pts[i - 1], pts[i], pts[i + 1]
        chain = _hull_chain(a, c, b, corners)
        if chain is not None:
            new = np.vstack((a, chain, b))
            old = float(np.hypot(*(c - a)) + np.hypot(*(b - c)))
            if path_length(new) < old and np.all(edges.segments_free(new[:-1], new[1:])):
                pts[i:i + 1] = list(chain)
                i += len(chain)
                continue
        i += 1
    return np.asarray(pts).reshape(-1, 2)


class Shortener:
    """Shortens paths against one fixed set of closed polygons.

    Building the obstacle index and the corner set is most of the cost of one
    :func:`simplify` call; a planner that shortens several candidate paths
    builds them once here.

    Parameters
    ----------
    polygons : sequence of numpy.ndarray
        The obstacles the paths must miss (already grown by the robot radius).
    config : ShortcutConfig, optional
    """

    def __init__(self, polygons: Sequence[np.ndarray],
                 config: ShortcutConfig | None = None) -> None:
        self.config = config or ShortcutConfig()
        self.obstacles = ObstacleMap()
        for i, poly in enumerate(polygons):
            self.obstacles.add(f'p{i}', poly)
        stored = [self.obstacles.polygon(k) for k in self.obstacles.ids()]
        self.edges = EdgeSet(stored)
        self.corners = outward_corners(stored, self.config.push)

    def is_free(self, path: np.ndarray) -> bool:
        """Whether every segment of ``path`` misses every (closed) polygon."""
        return bool(np.all(self.obstacles.segments_free(path[:-1], path[1:])))

    def simplify(self, path: np.ndarray) -> np.ndarray:
        """Shorten a collision-free path: alternate shortcuts and tightening.

        Parameters
        ----------
        path : numpy.ndarray
            Waypoints (k, 2), m, start first; every segment free of the polygons.

        Returns
        -------
        numpy.ndarray
            Waypoints with the same end points, no longer than ``path`` and free
            of every polygon; ``path`` itself (a copy) when nothing shorter was
            found or the input was not free to begin with.
        """
        cfg = self.config
        path = np.asarray(path, dtype=float).reshape(-1, 2)
        if len(path) < 3 or not self.is_free(path):
            return path.copy()
        best = path
        best_len = path_length(path)
        current = path
        for _ in range(cfg.rounds):
            current = tighten(shortcut_vertices(current, self.edges), self.edges,
                              self.corners)
            length = path_length(current)
            if length < best_len - cfg.tolerance:
                best, best_len = current, length
            else:
                break
        if best is path:
            return path.copy()
        cleaned = _drop_repeats(best, cfg.push)
        if self.is_free(cleaned):
            return cleaned
        # The fast checks assume free end points; the full test has the last word.
        return best if self.is_free(best) else path.copy()


def simplify(path: np.ndarray, polygons: Sequence[np.ndarray],
             config: ShortcutConfig | None = None) -> np.ndarray:
    """Shorten a collision-free path against closed polygons (see :class:`Shortener`)."""
    return Shortener(polygons, config).simplify(path)


def _drop_repeats(path: np.ndarray, tol: float) -> np.ndarray:
    """Remove interior waypoints within ``tol`` (m) of the previous kept one."""
    keep = [0]
    for k in range(1, len(path) - 1):
        if float(np.hypot(*(path[k] - path[keep[-1]]))) > tol:
            keep.append(k)
    if len(keep) > 1 and float(np.hypot(*(path[-1] - path[keep[-1]]))) <= tol:
        keep.pop()
    keep.append(len(path) - 1)
    return np.asarray(path[keep])
