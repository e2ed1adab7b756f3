"""Obstacle augmentation by the kinodynamic distance (RRT-QX §2, eqs. (6)-(7); §5).

RRT^X plans straight edges, but the robot, driven by a learned optimal controller of
unknown dynamics, follows curves. The safety core measures how far the robot strays
from the straight line of its current leg (the kinodynamic distance D_rob, eq. 6),
keeps the running maximum, and grows every detected obstacle by that maximum plus the
robot radius (the Minkowski sum with a disc, eq. 7) so that the planner's straight
edges keep the curved trajectory clear.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import Polygon

from rrtq_sim.polygon_set import PolygonSet

# m: how far outside a grown obstacle the robot is kept when the margin is capped.
KEEP_OUT = 0.05


def kinodynamic_distance(leg_start: npt.ArrayLike, leg_target: npt.ArrayLike,
                         position: npt.ArrayLike) -> float:
    """D_rob = |x̄₀ × x̄| / D₀ (RRT-QX eq. 6) in the plane: the robot's distance (m) from the
    straight line through the leg's start and target.

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


def grow_polygon(polygon: np.ndarray, radius: float, sides: int = 32) -> np.ndarray:
    """A polygon containing ``polygon`` ⊕ disc(``radius``), at most 0.5 % larger.

    The Minkowski sum with a disc is the polygon, plus each edge swept along its
    normal by ±radius (a rectangle), plus a disc at each vertex.  Each disc is
    replaced by the regular ``sides``-gon whose edges are tangent to it, which
    contains it, and the pieces are united.  (``shapely``'s ``buffer`` does not
    bound its chords: GEOS spans up to about two angle quanta with one chord, so
    scaling its distance by a fixed factor is not reliably conservative.)

    Returns the exterior ring (k, 2) without the closing vertex; a hole (free
    space enclosed by the obstacle) is filled, which no path can use anyway.
    """
    poly = np.asarray(polygon, dtype=float)
    if radius <= 0.0:
        return poly.copy()
    nxt = np.roll(poly, -1, axis=0)
    edge = nxt - poly
    length = np.linalg.norm(edge, axis=1, keepdims=True)
    normal = np.column_stack((-edge[:, 1], edge[:, 0])) / np.where(length > 0, length, 1.0)
    off = radius * normal
    rects = np.stack((poly + off, nxt + off, nxt - off, poly - off), axis=1)
    angles = 2.0 * np.pi * (np.arange(sides) + 0.5) / sides
    ring = (radius / np.cos(np.pi / sides)) * np.column_stack((np.cos(angles), np.sin(angles)))
    discs = poly[:, None, :] + ring[None, :, :]
    pieces = [Polygon(poly).buffer(0)]
    pieces += list(shapely.polygons(rects[length[:, 0] > 0]))
    pieces += list(shapely.polygons(discs))
    union = shapely.union_all(pieces)
    if union.geom_type != 'Polygon':
        union = max(getattr(union, 'geoms', [union]), key=lambda g: g.area)
    return np.asarray(union.exterior.coords, dtype=float)[:-1]


def augment(polygon: npt.ArrayLike, margin: float) -> np.ndarray:
    """The obstacle ⊕ a disc of radius ``margin`` (RRT-QX eq. 7), as a polygon containing it."""
    return grow_polygon(np.asarray(polygon, dtype=float), margin)


@dataclasses.dataclass(frozen=True)
class SafetyConfig:
    """Parameters of the safety monitor."""

    robot_radius: float = 0.0        # m, added to every margin
    growth_threshold: float = 0.05   # m; the augmented set is republished when the margin
    #                                  has grown by at least this since the last publication


class SafetyMonitor:
    """Running maximum of D_rob and the margin obstacles are grown by."""

    def __init__(self, config: SafetyConfig) -> None:
        self.config = config
        self.d_rob = 0.0
        self.d_rob_max = 0.0
        self.published_margin: float | None = None

    @property
    def margin(self) -> float:
        """Current growth (m): max D_rob + robot radius."""
        return self.d_rob_max + self.config.robot_radius

    def update(self, leg_start: npt.ArrayLike, leg_target: npt.ArrayLike,
               position: npt.ArrayLike) -> bool:
        """Account one step; True when the margin has grown enough to republish."""
        self.d_rob = kinodynamic_distance(leg_start, leg_target, position)
        self.d_rob_max = max(self.d_rob_max, self.d_rob)
        return (self.published_margin is None
                or self.margin >= self.published_margin + self.config.growth_threshold)

    def augmented(self, obstacles: Sequence[tuple[str, np.ndarray]],
                  position: npt.ArrayLike | None = None) -> list[tuple[str, np.ndarray]]:
        """Every obstacle grown by the current margin; records the margin as published.

        With the robot's ``position``, an obstacle is grown at most to ``KEEP_OUT`` short of
        the robot: a margin that grew while the robot was near an obstacle must not swallow
        the robot, or the planner, which plans from the robot's position, finds no way out.
        (Inside the true obstacle grown by the robot radius is a collision, not this case.)
        """
        self.published_margin = self.margin
        out = []
        for oid, poly in obstacles:
            margin = self.margin
            if position is not None:
                gap = float(shapely.Polygon(poly).distance(shapely.Point(
                    np.asarray(position, dtype=float)[:2])))
                margin = min(margin, max(gap - KEEP_OUT, 0.0))
            out.append((oid, augment(poly, margin)))
        return out


def clearance(position: npt.ArrayLike, polygons: PolygonSet | Sequence[np.ndarray],
              robot_radius: float) -> tuple[float, int]:
    """Distance (m) from the robot's disc to the nearest polygon (< 0 inside) and its index.

    (inf, -1) when there are no polygons. Give a :class:`PolygonSet` when the same
    polygons are asked about at every step.
    """
    shapes = polygons if isinstance(polygons, PolygonSet) else PolygonSet(polygons)
    value, index = shapes.nearest(np.asarray(position, dtype=float)[:2])
    return value - robot_radius, index
