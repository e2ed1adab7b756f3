"""Segment and point tests against polygonal obstacles, vectorised over edges.

Obstacles are closed sets: a segment that touches a polygon's boundary, or a
point on it, is in collision.  A segment intersects a closed polygon exactly
when it crosses or touches one of the polygon's edges or its start point lies
inside the polygon (if the start is outside and the end inside, the segment
crosses the boundary).  Every test here uses that reduction, with orientation
signs evaluated for all (segment, edge) pairs at once.
"""

from __future__ import annotations

import numpy as np


def segments_cross_edges(
    p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """Test segments ``p[i]q[i]`` against edges ``a[j]b[j]`` (closed sets).

    Parameters
    ----------
    p, q : numpy.ndarray
        Segment end points, shape (k, 2), in metres.
    a, b : numpy.ndarray
        Edge end points, shape (m, 2), in metres.

    Returns
    -------
    numpy.ndarray
        Boolean (k, m): segment i touches or crosses edge j.
    """
    px = p[:, 0:1]
    py = p[:, 1:2]
    qx = q[:, 0:1]
    qy = q[:, 1:2]
    ax = a[:, 0]
    ay = a[:, 1]
    bx = b[:, 0]
    by = b[:, 1]
    dx = qx - px
    dy = qy - py
    o1 = dx * (ay - py) - dy * (ax - px)
    o2 = dx * (by - py) - dy * (bx - px)
    ex = bx - ax
    ey = by - ay
    o3 = ex * (py - ay) - ey * (px - ax)
    o4 = ex * (qy - ay) - ey * (qx - ax)
    hit = (o1 * o2 <= 0.0) & (o3 * o4 <= 0.0)
    colinear = (o1 == 0.0) & (o2 == 0.0)
    if colinear.any():
        # All four orientations vanish only on one line: overlap is then a box test.
        overlap = (
            (np.minimum(px, qx) <= np.maximum(ax, bx))
            & (np.minimum(ax, bx) <= np.maximum(px, qx))
            & (np.minimum(py, qy) <= np.maximum(ay, by))
            & (np.minimum(ay, by) <= np.maximum(py, qy))
        )
        hit &= ~colinear | overlap
    return np.asarray(hit, dtype=bool)


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Test points against a closed polygon (the boundary counts as inside).

    Parameters
    ----------
    points : numpy.ndarray
        Shape (n, 2), metres.
    polygon : numpy.ndarray
        Vertices, shape (k, 2), metres, in either orientation, not repeated.

    Returns
    -------
    numpy.ndarray
        Boolean (n,).
    """
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    x = points[:, 0:1]
    y = points[:, 1:2]
    ax = a[:, 0]
    ay = a[:, 1]
    bx = b[:, 0]
    by = b[:, 1]
    straddle = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = ax + (y - ay) * (bx - ax) / (by - ay)
    inside = np.count_nonzero(straddle & (x < x_cross), axis=1) % 2 == 1
    cross = (bx - ax) * (y - ay) - (by - ay) * (x - ax)
    on_edge = (
        (cross == 0.0)
        & (np.minimum(ax, bx) <= x)
        & (x <= np.maximum(ax, bx))
        & (np.minimum(ay, by) <= y)
        & (y <= np.maximum(ay, by))
    )
    return np.asarray(inside | on_edge.any(axis=1), dtype=bool)


def segments_hit_polygon(p: np.ndarray, q: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Test segments ``p[i]q[i]`` against one closed polygon.

    Parameters
    ----------
    p, q : numpy.ndarray
        Shape (k, 2), metres.
    polygon : numpy.ndarray
        Shape (m, 2), metres.

    Returns
    -------
    numpy.ndarray
        Boolean (k,): segment i intersects the closed polygon.
    """
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    hit: np.ndarray = np.asarray(segments_cross_edges(p, q, a, b).any(axis=1))
    rest = ~hit
    if rest.any():
        hit[rest] = points_in_polygon(p[rest], polygon)
    return hit


def clean_polygon(polygon: np.ndarray) -> np.ndarray:
    """Validate a polygon and drop a repeated closing vertex.

    Parameters
    ----------
    polygon : array_like
        Shape (k, 2), k >= 3 after cleaning, metres.

    Returns
    -------
    numpy.ndarray
        Float copy, shape (k, 2).
    """
    poly = np.array(polygon, dtype=float)
    if poly.ndim != 2 or poly.shape[1] != 2:
        raise ValueError(f"polygon must have shape (k, 2), got {poly.shape}")
    if poly.shape[0] > 3 and np.array_equal(poly[0], poly[-1]):
        poly = poly[:-1]
    if poly.shape[0] < 3 or not np.all(np.isfinite(poly)):
        raise ValueError("polygon needs at least 3 finite vertices")
    return poly


class ObstacleMap:
    """The current obstacle set O, with all polygon edges in flat arrays.

    Edges of every polygon are concatenated (start ``_a``, end ``_b``, owner
    ``_owner``) with per-edge bounding boxes, so a query first keeps the edges
    whose box overlaps the query's box and then runs the exact test on those.
    """

    def __init__(self) -> None:
        self._polygons: dict[str, np.ndarray] = {}
        self._rebuild()

    def _rebuild(self) -> None:
        polys = list(self._polygons.values())
        if polys:
            self._a = np.concatenate(polys)
            self._b = np.concatenate([np.roll(p, -1, axis=0) for p in polys])
            self._owner = np.concatenate(
                [np.full(p.shape[0], i, dtype=np.intp) for i, p in enumerate(polys)]
            )
        else:
            self._a = np.zeros((0, 2))
            self._b = np.zeros((0, 2))
            self._owner = np.zeros(0, dtype=np.intp)
        self._order = polys
        self._lo = np.minimum(self._a, self._b)
        self._hi = np.maximum(self._a, self._b)
        self._poly_lo = np.array([p.min(axis=0) for p in polys]).reshape(-1, 2)
        self._poly_hi = np.array([p.max(axis=0) for p in polys]).reshape(-1, 2)

    def __contains__(self, obstacle_id: object) -> bool:
        return obstacle_id in self._polygons

    def __len__(self) -> int:
        return len(self._polygons)

    def ids(self) -> list[str]:
        """Obstacle ids in insertion order."""
        return list(self._polygons)

    def polygon(self, obstacle_id: str) -> np.ndarray:
        """Return the stored (cleaned) polygon of ``obstacle_id``."""
        return self._polygons[obstacle_id]

    def add(self, obstacle_id: str, polygon: np.ndarray) -> np.ndarray:
        """Insert a polygon; returns the cleaned copy that is stored."""
        poly = clean_polygon(polygon)
        self._polygons[obstacle_id] = poly
        self._rebuild()
        return poly

    def remove(self, obstacle_id: str) -> np.ndarray:
        """Remove and return the polygon of ``obstacle_id``."""
        poly = self._polygons.pop(obstacle_id)
        self._rebuild()
        return poly

    def point_free(self, point: np.ndarray) -> bool:
        """Return True when ``point`` (shape (2,)) lies outside every closed polygon.

        One crossing-number pass over the edges of all polygons whose box
        holds the point; parity is counted per polygon with ``bincount``.
        """
        if not self._order:
            return True
        x = float(point[0])
        y = float(point[1])
        lo = self._poly_lo
        hi = self._poly_hi
        inbox = (lo[:, 0] <= x) & (x <= hi[:, 0]) & (lo[:, 1] <= y) & (y <= hi[:, 1])
        if not inbox.any():
            return True
        e = inbox[self._owner].nonzero()[0]
        a = self._a[e]
        b = self._b[e]
        ax = a[:, 0]
        ay = a[:, 1]
        bx = b[:, 0]
        by = b[:, 1]
        cross = (bx - ax) * (y - ay) - (by - ay) * (x - ax)
        on_edge = (
            (cross == 0.0)
            & (self._lo[e, 0] <= x)
            & (x <= self._hi[e, 0])
            & (self._lo[e, 1] <= y)
            & (y <= self._hi[e, 1])
        )
        if on_edge.any():
            return False
        straddle = (ay > y) != (by > y)
        # x < x-crossing of the edge, written without division: the sign of
        # cross is that of (by - ay) when the point is left of the edge.
        left = straddle & ((cross > 0.0) == (by > ay))
        counts = np.bincount(self._owner[e[left]], minlength=len(self._order))
        return not np.any(counts & 1)

    def segments_free_from(
        self, start: np.ndarray, ends: np.ndarray, start_free: bool = False
    ) -> np.ndarray:
        """Which segments from one common start point miss every obstacle.

        Parameters
        ----------
        start : numpy.ndarray
            Shape (2,), metres.
        ends : numpy.ndarray
            Shape (k, 2), metres.
        start_free : bool
            The caller already knows ``start`` is outside every polygon.

        Returns
        -------
        numpy.ndarray
            Boolean (k,), True for a collision-free segment.
        """
        k = ends.shape[0]
        if k == 0 or self._a.shape[0] == 0:
            return np.ones(k, dtype=bool)
        if not start_free and not self.point_free(start):
            return np.zeros(k, dtype=bool)
        lo = np.minimum(ends.min(axis=0), start)
        hi = np.maximum(ends.max(axis=0), start)
        near = np.flatnonzero(
            (self._lo[:, 0] <= hi[0])
            & (self._hi[:, 0] >= lo[0])
            & (self._lo[:, 1] <= hi[1])
            & (self._hi[:, 1] >= lo[1])
        )
        if near.shape[0] == 0:
            return np.ones(k, dtype=bool)
        p = start.reshape(1, 2)
        hit = segments_cross_edges(p, ends, self._a[near], self._b[near])
        return np.asarray(~hit.any(axis=1), dtype=bool)

    def segments_free(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Which segments ``p[i]q[i]`` (shape (k, 2) each) miss every obstacle."""
        k = p.shape[0]
        free = np.ones(k, dtype=bool)
        if k == 0 or not self._order:
            return free
        lo = np.minimum(p, q)
        hi = np.maximum(p, q)
        for i, poly in enumerate(self._order):
            cand = np.flatnonzero(
                np.all((lo <= self._poly_hi[i]) & (hi >= self._poly_lo[i]), axis=1)
            )
            if cand.shape[0]:
                free[cand[segments_hit_polygon(p[cand], q[cand], poly)]] = False
        return free
