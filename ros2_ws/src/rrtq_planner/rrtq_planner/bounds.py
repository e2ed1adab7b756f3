"""The world's bounds as an obstacle the robot keeps inside (no rclpy).

A scenario's ``bounds`` (x_min, x_max, y_min, y_max) are a rectangle the robot's disc must
stay in: its outside is an obstacle like any other, known from the start. The planner:
:class:`Region`, the bounds shrunk by the margin the obstacles are grown by (robot radius
included), is RRT^X's configuration space. It is convex, so a segment between two of its
points lies in it: the planner checks where its nodes are, never its edges against the
boundary, and its polygon tests see only the obstacles.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ['Bounds', 'Region']

Bounds = tuple[float, float, float, float]
"""(x_min, x_max, y_min, y_max), m."""

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

