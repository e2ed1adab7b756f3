"""The world's bounds as an obstacle the robot keeps inside (no rclpy).

A scenario's ``bounds`` (x_min, x_max, y_min, y_max) are a rectangle the robot's disc must
stay in: its outside is an obstacle like any other, known from the start. Two sides use it:

* the planner: :class:`Region`, the bounds shrunk by the margin the obstacles are grown by
  (robot radius included), is RRT^X's configuration space. It is convex, so a segment
  between two of its points lies in it: the planner checks where its nodes are, never its
  edges against the boundary, and its polygon tests see only the obstacles;
* the safety node: :func:`wall_distance` and :func:`wall_ahead`, the boundary as the
  nearest obstacle and as the obstacle ahead along the velocity, which the controller's
  keep-off pushes the robot away from (back inside).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ['Bounds', 'Region', 'wall_distance', 'wall_ahead']

Bounds = tuple[float, float, float, float]
"""(x_min, x_max, y_min, y_max), m."""

# Inward unit normals of the four edges: x_min, x_max, y_min, y_max.
_INWARD = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


def _gaps(p: np.ndarray, bounds: Bounds, inset: float) -> np.ndarray:
    """(4,) signed distance (m) of ``p`` inside each edge moved in by ``inset`` (< 0: beyond)."""
    x0, x1, y0, y1 = bounds
    return np.array([p[0] - (x0 + inset), (x1 - inset) - p[0],
                     p[1] - (y0 + inset), (y1 - inset) - p[1]])


class Region:
    """The bounds shrunk by ``margin`` on every side: the closed box the planner's nodes lie in.

    Parameters
    ----------
    bounds : (x_min, x_max, y_min, y_max)
        m.
    margin : float
        m, >= 0; on an axis narrower than twice the margin the box is the middle line.

    Attributes
    ----------
    lo, span : numpy.ndarray
        (2,), m: the lower corner and the size; the box is [lo, lo + span] (``hi``).
    """

    def __init__(self, bounds: Bounds, margin: float) -> None:
        x0, x1, y0, y1 = bounds
        self.bounds = bounds
        self.margin = float(margin)
        sx = min(self.margin, 0.5 * (x1 - x0))
        sy = min(self.margin, 0.5 * (y1 - y0))
        self.lo = np.array([x0 + sx, y0 + sy])
        # The size as RRT^X has always drawn its samples (x1 - x0 - 2 r): the same samples.
        self.span = np.array([x1 - x0 - 2 * sx, y1 - y0 - 2 * sy])
        self.hi = self.lo + self.span

    def contains(self, points: npt.ArrayLike) -> np.ndarray:
        """(k,) bool: which of the points (k, 2), m, lie in the closed box."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        return np.asarray(np.all((pts >= self.lo) & (pts <= self.hi), axis=1))

    def clamp(self, point: npt.ArrayLike) -> np.ndarray:
        """The point of the box nearest ``point`` (2,), m (the point itself when inside)."""
        return np.asarray(np.clip(np.asarray(point, dtype=float).reshape(2), self.lo, self.hi))


def wall_distance(position: npt.ArrayLike, bounds: Bounds,
                  robot_radius: float) -> tuple[float, tuple[float, float]]:
    """The robot disc's distance (m) to the boundary and the unit vector back inside.

    Inside the bounds: the distance from the centre to the nearest edge less the radius
    (< 0: the disc crosses it), and that edge's inward normal. With the centre outside:
    minus the distance to the rectangle less the radius, and the unit vector toward the
    rectangle's nearest point. The direction is the way away from the obstacle, as for a
    polygon (:func:`rrtq_planner.safety.nearest_obstacle`), and is known even where the
    robot overlaps it.
    """
    p = np.asarray(position, dtype=float)[:2]
    gaps = _gaps(p, bounds, 0.0)
    if gaps.min() >= 0.0:
        i = int(np.argmin(gaps))
        return float(gaps[i]) - robot_radius, (float(_INWARD[i, 0]), float(_INWARD[i, 1]))
    x0, x1, y0, y1 = bounds
    back = np.clip(p, (x0, y0), (x1, y1)) - p
    depth = float(np.hypot(*back))
    return -depth - robot_radius, (float(back[0] / depth), float(back[1] / depth))


def wall_ahead(position: npt.ArrayLike, velocity: npt.ArrayLike, bounds: Bounds,
               robot_radius: float, look_ahead: float) -> tuple[float, tuple[float, float]]:
    """How far (m) the robot's disc moves along ``velocity`` before it meets the boundary.

    The centre meets an edge moved in by the robot radius; only the edges the robot heads
    toward count. Returns the distance and that edge's inward normal (toward the robot);
    (inf, (0, 0)) at rest or with no edge within ``look_ahead``; 0 when the disc already
    crosses an edge it heads further into (a polygon it overlaps gives no direction there:
    :func:`rrtq_planner.safety.obstacle_ahead`; an edge does).
    """
    p = np.asarray(position, dtype=float)[:2]
    v = np.asarray(velocity, dtype=float)[:2]
    speed = float(np.hypot(*v))
    if look_ahead <= 0.0 or not speed > 1e-9:
        return math.inf, (0.0, 0.0)
    closing = -(_INWARD @ v) / speed            # > 0: heading toward that edge
    toward = np.flatnonzero(closing > 0.0)
    if toward.shape[0] == 0:
        return math.inf, (0.0, 0.0)
    gaps = _gaps(p, bounds, robot_radius)[toward]
    travel = np.maximum(gaps, 0.0) / closing[toward]
    j = int(np.argmin(travel))
    if travel[j] > look_ahead:
        return math.inf, (0.0, 0.0)
    i = int(toward[j])
    return float(travel[j]), (float(_INWARD[i, 0]), float(_INWARD[i, 1]))
