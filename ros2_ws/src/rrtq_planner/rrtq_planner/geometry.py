"""Segment and point tests against polygonal obstacles, vectorised over edges.

Obstacles are closed sets: a segment that touches a polygon's boundary, or a
point on it, is in collision.  A segment intersects a closed polygon exactly
when it crosses or touches one of the polygon's edges or its start point lies
inside the polygon (if the start is outside and the end inside, the segment
crosses the boundary).  The functions here use that reduction, with orientation
signs evaluated for all (segment, edge) pairs at once; :class:`ObstacleMap`, the
planner's per-iteration test against the whole set, asks GEOS (shapely) the same
closed-set question of the union of the polygons.
"""

from __future__ import annotations

import numpy as np
import shapely


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


def _closed_set(polygon: np.ndarray) -> shapely.Geometry:
    """The polygon as GEOS geometry; a self-intersecting ring by the even-odd rule.

    ``make_valid`` rebuilds such a ring from its noded edges with alternating
    inside and outside, the parity :func:`points_in_polygon` counts.
    """
    geom = shapely.Polygon(polygon)
    return geom if shapely.is_valid(geom) else shapely.make_valid(geom)


class ObstacleMap:
    """The current obstacle set O, queried through one prepared GEOS union.

    Point and segment queries are the planner's innermost collision tests, one
    batch per iteration.  They go to shapely's vectorised predicates on the
    prepared union of the closed polygons (``intersects`` counts touching, as
    the tests above do): on rand_Static grown by 0.5 m (35 polygons, 1,560
    edges) a point costs ~5 us and a batch of 25 segments ~40 us, against
    ~70 us and ~150 us for the numpy edge tests with bounding-box culling that
    this class ran before (measured side by side, 2026-12-01;
    ``benchmarks/planner_vs_ompl.py`` reports the GEOS calls).  The union is rebuilt
    lazily, at the first query after a change, so a batch of obstacle
    updates pays for one.
    """

    def __init__(self) -> None:
        self._polygons: dict[str, np.ndarray] = {}
        self._union: shapely.Geometry | None = None
        self._stale = False

    def _prepared(self) -> shapely.Geometry | None:
        if self._stale:
            polys = [_closed_set(p) for p in self._polygons.values()]
            self._union = shapely.union_all(polys) if polys else None
            if self._union is not None:
                shapely.prepare(self._union)
            self._stale = False
        return self._union

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
        self._stale = True
        return poly

    def remove(self, obstacle_id: str) -> np.ndarray:
        """Remove and return the polygon of ``obstacle_id``."""
        poly = self._polygons.pop(obstacle_id)
        self._stale = True
        return poly

    def point_free(self, point: np.ndarray | tuple[float, float]) -> bool:
        """Return True when ``point`` (shape (2,)) lies outside every closed polygon."""
        union = self._prepared()
        return union is None or not shapely.intersects_xy(union, float(point[0]),
                                                          float(point[1]))

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
            The caller already knows ``start`` is outside every polygon (the
            segment test covers the start point either way).

        Returns
        -------
        numpy.ndarray
            Boolean (k,), True for a collision-free segment.
        """
        return self.segments_free(np.broadcast_to(start, ends.shape), ends)

    def segments_free(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Which segments ``p[i]q[i]`` (shape (k, 2) each) miss every obstacle.

        A zero-length segment is its point.
        """
        k = p.shape[0]
        union = self._prepared()
        if k == 0 or union is None:
            return np.ones(k, dtype=bool)
        coords = np.empty((k, 2, 2))
        coords[:, 0] = p
        coords[:, 1] = q
        return np.asarray(~shapely.intersects(union, shapely.linestrings(coords)), dtype=bool)
