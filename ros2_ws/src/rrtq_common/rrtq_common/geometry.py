"""Planar polygon geometry: validation, circles as polygons, containment, distance.

Polygons are ``(k, 2)`` float arrays of vertices (m) without a repeated closing
vertex; either orientation is accepted.  The queries are vectorised over query
points and polygon edges because the perception and safety loops call them for
every obstacle at every step.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = [
    'polygon_from_circle',
    'as_polygon',
    'polygon_area',
    'point_in_polygon',
    'point_polygon_distance',
    'disc_intersects_polygon',
    'kinodynamic_distance',
    'ray_distance',
    'segment_distance',
]


def as_polygon(polygon: npt.ArrayLike) -> np.ndarray:
    """Validate and return a polygon as a float ``(k, 2)`` array.

    Raises
    ------
    ValueError
        If it is not ``(k, 2)`` with ``k >= 3``, not finite, or has zero area.
    """
    poly = np.asarray(polygon, dtype=float)
    if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3:
        raise ValueError(f'a polygon needs at least 3 vertices (k, 2), got shape {poly.shape}')
    if not np.all(np.isfinite(poly)):
        raise ValueError('polygon vertices must be finite')
    if polygon_area(poly) == 0.0:
        raise ValueError('polygon has zero area (all vertices collinear)')
    return poly


def polygon_area(polygon: npt.ArrayLike) -> float:
    """Signed area by the shoelace formula, m^2 (> 0 counter-clockwise)."""
    poly = np.asarray(polygon, dtype=float)
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def polygon_from_circle(center: npt.ArrayLike, radius: float, vertices: int = 32) -> np.ndarray:
    """Regular polygon circumscribing a circle (counter-clockwise).

    The vertices sit at ``radius / cos(pi / vertices)`` so that every edge is tangent
    to the circle: the polygon contains the circle, which keeps collision checks on
    the polygon conservative.

    Parameters
    ----------
    center : array_like, shape (2,)
        Circle centre, m.
    radius : float
        Circle radius, m (> 0).
    vertices : int
        Number of vertices (>= 3).

    Returns
    -------
    numpy.ndarray, shape (vertices, 2)
    """
    c = np.asarray(center, dtype=float).reshape(-1)
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise ValueError(f'center must be a finite (2,) point, got {center!r}')
    if not (math.isfinite(radius) and radius > 0.0):
        raise ValueError(f'radius must be finite and > 0, got {radius!r}')
    if vertices < 3:
        raise ValueError(f'vertices must be >= 3, got {vertices}')
    angles = 2.0 * np.pi * np.arange(vertices) / vertices
    r_out = radius / math.cos(math.pi / vertices)
    return c + r_out * np.column_stack((np.cos(angles), np.sin(angles)))


def _points(points: npt.ArrayLike) -> np.ndarray:
    pts = np.asarray(points, dtype=float)
    if pts.shape[-1:] != (2,):
        raise ValueError(f'points must have shape (..., 2), got {pts.shape}')
    return pts


def _query(points: npt.ArrayLike,
           polygon: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Query points (..., 2), the same flattened (N, 2), the polygon (k, 2)."""
    pts = _points(points)
    return pts, pts.reshape(-1, 2), np.asarray(polygon, dtype=float)


def point_in_polygon(points: npt.ArrayLike, polygon: npt.ArrayLike) -> np.ndarray:
    """Even-odd containment test.

    Parameters
    ----------
    points : array_like, shape (..., 2)
        Query points, m.
    polygon : array_like, shape (k, 2)

    Returns
    -------
    numpy.ndarray of bool, shape (...)
        Points exactly on the boundary may go either way; use
        :func:`point_polygon_distance` when the boundary matters.
    """
    pts, flat, poly = _query(points, polygon)
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    px, py = flat[:, 0:1], flat[:, 1:2]  # (N, 1) against (k,) edges
    straddles = (y0 > py) != (y1 > py)
    with np.errstate(divide='ignore', invalid='ignore'):
        x_cross = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    crossings = straddles & (px < x_cross)
    inside = (np.count_nonzero(crossings, axis=1) % 2) == 1
    return inside.reshape(pts.shape[:-1])


def point_polygon_distance(points: npt.ArrayLike, polygon: npt.ArrayLike) -> np.ndarray:
    """Euclidean distance from each point to a polygon, 0 inside.

    Parameters
    ----------
    points : array_like, shape (..., 2)
        Query points, m.
    polygon : array_like, shape (k, 2)

    Returns
    -------
    numpy.ndarray, shape (...)
        Distance in m.
    """
    pts, flat, poly = _query(points, polygon)
    a = poly[None, :, :]  # (1, k, 2)
    ab = np.roll(poly, -1, axis=0)[None, :, :] - a
    ap = flat[:, None, :] - a  # (N, k, 2)
    len2 = np.einsum('ijk,ijk->ij', ab, ab)
    # Degenerate (repeated-vertex) edges have len2 = 0; their closest point is a.
    with np.errstate(divide='ignore', invalid='ignore'):
        s = np.where(len2 > 0.0, np.einsum('ijk,ijk->ij', ap, ab) / len2, 0.0)
    s = np.clip(s, 0.0, 1.0)
    diff = ap - s[..., None] * ab
    dist = np.sqrt(np.min(np.einsum('ijk,ijk->ij', diff, diff), axis=1))
    dist[point_in_polygon(flat, poly)] = 0.0
    return dist.reshape(pts.shape[:-1])


def disc_intersects_polygon(center: npt.ArrayLike, radius: float, polygon: npt.ArrayLike) -> bool:
    """True when the closed disc touches or overlaps the polygon (or contains it)."""
    return bool(point_polygon_distance(center, polygon) <= radius)


def kinodynamic_distance(leg_start: npt.ArrayLike, leg_target: npt.ArrayLike,
                         position: npt.ArrayLike) -> float:
    """D_rob = |x̄₀ × x̄| / D₀ (RRT-QX eq. 6) in the plane.

    The robot's distance (m) from the straight line through the leg's start and target.

    The cross product and D₀ are taken over the position components, which makes D_rob
    the perpendicular distance to the leg's line (the paper's x̄ carries velocities too,
    whose cross product has no geometric meaning). A leg of zero length has no line:
    D_rob is then the distance from the target.
    """
    x0bar = np.asarray(leg_start, dtype=float)[:2] - np.asarray(leg_target, dtype=float)[:2]
    xbar = np.asarray(position, dtype=float)[:2] - np.asarray(leg_target, dtype=float)[:2]
    d0 = math.hypot(*x0bar)
    if d0 < 1e-12:
        return math.hypot(*xbar)
    return abs(x0bar[0] * xbar[1] - x0bar[1] * xbar[0]) / d0



def ray_distance(leg_start: npt.ArrayLike, leg_target: npt.ArrayLike,
                 position: npt.ArrayLike) -> float:
    """The robot's distance (m) from the ray from the leg's start through its target.

    At least D_rob (:func:`kinodynamic_distance`, the distance from the leg's *line*), and
    larger where the robot is behind the start: a robot drifting backwards along its line,
    away from its target, leaves the region a plan keeps clear around its edges (the
    segment grown by the margin) with D_rob unchanged. Past the target it is D_rob: a
    learning policy's overshoot there is measured as the paper measures it. A leg of zero
    length is its start: the distance from it.
    """
    return _clipped_distance(leg_start, leg_target, position, math.inf)


def segment_distance(leg_start: npt.ArrayLike, leg_target: npt.ArrayLike,
                     position: npt.ArrayLike) -> float:
    """The robot's distance (m) from the segment from the leg's start to its target.

    :func:`ray_distance` clipped at the target as well: for a leg too short to have a line
    (holding station), where a robot past the target has left it as much as one behind the
    start.
    """
    return _clipped_distance(leg_start, leg_target, position, 1.0)


def _clipped_distance(leg_start: npt.ArrayLike, leg_target: npt.ArrayLike,
                      position: npt.ArrayLike, upper: float) -> float:
    """m: the distance from the points start + s (target - start), 0 <= s <= ``upper``."""
    a = np.asarray(leg_start, dtype=float)[:2]
    ab = np.asarray(leg_target, dtype=float)[:2] - a
    ap = np.asarray(position, dtype=float)[:2] - a
    len2 = float(ab @ ab)
    s = 0.0 if len2 < 1e-24 else min(max(float(ap @ ab) / len2, 0.0), upper)
    return math.hypot(*(ap - s * ab))
