"""The referee's judgement of a step: the true pose against the true obstacles and the bounds.

Simulator side only: it takes the robot's true position (/odom/truth) and what physically
exists (:class:`rrtq_common.world.TrueObstacles`), never what any robot node believes. The
obstacle spawner publishes it on /referee/status every step; the supervisor's mission
monitor (:mod:`rrtq_bringup.mission`) ends a run on it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.polygon_set import LivePolygons
from rrtq_common.world import ObstacleSpec

__all__ = ['Bounds', 'Judgement', 'Referee', 'bounds_clearance']

Bounds = tuple[tuple[float, float], tuple[float, float]]
"""((x_min, x_max), (y_min, y_max)), m."""


def bounds_clearance(position: npt.ArrayLike, bounds: Bounds) -> float:
    """Signed distance (m) of ``position`` to the boundary of ``bounds``: > 0 inside.

    Outside it is minus the distance to the nearest point of the rectangle; on its edge 0.
    """
    x, y = np.asarray(position, dtype=float)[:2]
    (x0, x1), (y0, y1) = bounds
    outside_x = max(x0 - x, 0.0, x - x1)
    outside_y = max(y0 - y, 0.0, y - y1)
    if outside_x > 0.0 or outside_y > 0.0:
        return -math.hypot(outside_x, outside_y)
    return float(min(x - x0, x1 - x, y - y0, y1 - y))


@dataclass(frozen=True)
class Judgement:
    """One step of :meth:`Referee.judge`."""

    clearance: float
    """m, from the robot's disc to the nearest existing obstacle (< 0: overlap; inf: none)."""
    nearest: str
    """Id of that obstacle ('' when none exists)."""
    collision: bool
    """The robot's disc has met an obstacle at this step or before (latched)."""
    bounds_clearance: float
    """m, of the robot's centre to the boundary of the bounds (< 0: outside)."""
    out_of_bounds: bool
    """The robot's centre has left the bounds at this step or before (latched)."""


class Referee:
    """Judges the robot's true position step by step; collision and out-of-bounds latch.

    Parameters
    ----------
    robot_radius : float
        m; obstacles are judged against the robot's disc.
    bounds : Bounds
        The scenario's bounds, m; the robot's centre must stay inside (edge included).
    """

    def __init__(self, robot_radius: float, bounds: Bounds) -> None:
        self.robot_radius = float(robot_radius)
        self.bounds = bounds
        self.collided = False
        self.left_bounds = False
        self._shapes = LivePolygons()

    def clearance(self, position: npt.ArrayLike,
                  existing: Sequence[ObstacleSpec]) -> tuple[float, int]:
        """Signed gap (m) of the robot's disc to the nearest of ``existing`` and its index.

        Negative when they overlap, also inside an obstacle at robot radius 0; (inf, -1)
        when nothing exists.
        """
        value, index = self._shapes.update(existing).nearest(
            np.asarray(position, dtype=float)[:2])
        return value - self.robot_radius, index

    def judge(self, position: npt.ArrayLike, existing: Sequence[ObstacleSpec]) -> Judgement:
        """The step of the robot at ``position`` (m) among the ``existing`` obstacles."""
        gap, index = self.clearance(position, existing)
        margin = bounds_clearance(position, self.bounds)
        self.collided = self.collided or gap < 0.0
        self.left_bounds = self.left_bounds or margin < 0.0
        return Judgement(clearance=float(gap), nearest=existing[index].id if index >= 0 else '',
                         collision=self.collided, bounds_clearance=margin,
                         out_of_bounds=self.left_bounds)
