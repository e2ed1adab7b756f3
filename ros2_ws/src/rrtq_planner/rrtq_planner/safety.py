"""Obstacle augmentation by the kinodynamic distance (RRT-QX §2, eqs. (6)-(7); §5).

RRT^X plans straight edges, but the robot, driven by a learned optimal controller of
unknown dynamics, follows curves. The safety core measures how far the robot strays
from the straight line of its current leg (the kinodynamic distance D_rob, eq. 6),
keeps the running maximum, and grows every detected obstacle by that maximum plus the
robot radius (the Minkowski sum with a disc, eq. 7) so that the planner's straight
edges keep the curved trajectory clear.

It knows only what the robot knows: its odometry, its map (the detected obstacles) and the
controller's leg. Clearance and collision here are against that map; the truth is the
referee's (:mod:`rrtq_sim.referee`), on the simulator's side.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import Polygon

from rrtq_common.geometry import kinodynamic_distance
from rrtq_common.lockstep import OnChange
from rrtq_common.polygon_set import PolygonSet
from rrtq_common.settings import check, setting

from .bounds import wall_ahead, wall_distance

Obstacles = list[tuple[str, np.ndarray]]

# m: how far outside a grown obstacle the robot is kept when the margin is capped.
KEEP_OUT = 0.05


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
    assert isinstance(union, Polygon)
    return np.array(union.exterior.coords, dtype=float)[:-1]


def augment(polygon: npt.ArrayLike, margin: float) -> np.ndarray:
    """The obstacle ⊕ a disc of radius ``margin`` (RRT-QX eq. 7), as a polygon containing it."""
    return grow_polygon(np.asarray(polygon, dtype=float), margin)


class GrownCache:
    """:func:`grow_polygon` of a set of obstacles, reusing the last set's unchanged ones.

    A grown obstacle costs about 1.5 ms (a union of a disc per vertex and a strip per edge);
    the safety node grows its whole map again at every change of the detected set, while
    most of it is the same obstacles by the same radius. Measured on forest_100 (286 trees,
    ``benchmarks/safety_step.py``): 0.45 s for a republication that regrows all. An entry is
    reused only for the same id, radius and vertices, so the result is the same as growing
    afresh; entries not asked for again in a call are dropped. The rings returned are shared:
    callers must not modify them.
    """

    def __init__(self) -> None:
        self._last: dict[tuple[str, float, bytes], np.ndarray] = {}
        self.grown = 0
        """Obstacles grown afresh so far (the others were reused)."""

    def grow(self, items: Sequence[tuple[str, np.ndarray, float]]) -> list[np.ndarray]:
        """(id, polygon, radius) per obstacle -> the grown rings, in order."""
        now: dict[tuple[str, float, bytes], np.ndarray] = {}
        out = []
        for oid, polygon, radius in items:
            poly = np.ascontiguousarray(polygon, dtype=float)
            key = (oid, float(radius), poly.tobytes())
            ring = now.get(key)
            if ring is None:
                ring = self._last.get(key)
            if ring is None:
                ring = grow_polygon(poly, float(radius))
                self.grown += 1
            now[key] = ring
            out.append(ring)
        self._last = now
        return out


@dataclasses.dataclass(frozen=True)
class SafetyConfig:
    """Parameters of the safety monitor (the margin is the paper's: the running maximum)."""

    robot_radius: float = setting(0.0, unit='m', low=0.0, doc='added to every margin')
    growth_threshold: float = setting(0.05, unit='m', low=0.0, doc='the augmented set is '
                                      'republished when the margin has changed (grown, or '
                                      'shrunk under safety.margin conformal or learned_bound) '
                                      'by at least this since the last publication')
    look_ahead: float = setting(5.0, unit='m', low=0.0, doc='how far along the robot\'s '
                                'velocity the first detected obstacle it would meet is looked '
                                'for (/safety/status ahead_distance; 0: not)')
    bounds: tuple[float, float, float, float] | None = setting(
        None, unit='m', doc="the scenario's bounds x_min x_max y_min y_max: an obstacle the "
        "robot's disc keeps inside (nearest and ahead), and where learned_bound learns its "
        'field; None: none given (learned_bound refuses it)')

    def __post_init__(self) -> None:
        check(self)
        if self.bounds is not None and len(self.bounds) != 4:
            raise ValueError(f'bounds must be x_min x_max y_min y_max, got {self.bounds}')

    @property
    def region(self) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """The bounds as ((x_min, x_max), (y_min, y_max)), m (None: none given)."""
        if self.bounds is None:
            return None
        x0, x1, y0, y1 = self.bounds
        return (x0, x1), (y0, y1)


@dataclasses.dataclass(frozen=True)
class Leg:
    """The controller's current leg, as its state reports it."""

    index: int
    start: tuple[float, float]     # m
    target: tuple[float, float]    # m
    d0: float                      # m; 0 while the controller has no plan


@dataclasses.dataclass(frozen=True)
class SafetyStep:
    """One step of :meth:`SafetyMonitor.step`: what the safety node publishes and logs."""

    augmented: Obstacles | None
    """The detected obstacles grown by the margin, when they are to be republished."""
    augmented_stamp_ns: int
    """Stamp of the latest augmented set published."""
    d_rob: float
    d_rob_max: float
    margin: float
    clearance: float
    """m, from the robot's disc to the nearest *detected* obstacle, where the odometry puts
    the robot (< 0: overlap; inf: none detected): :attr:`obstacle_distance`."""
    nearest: str
    """Id of that obstacle ('' when there is none)."""
    collision: bool
    """The odometry has put the robot's disc onto a detected obstacle at this step or
    before (latched)."""
    new_collision: bool
    """It did at this step."""
    leg_index: int
    local_margins: dict[str, float] = dataclasses.field(default_factory=dict)
    """m, robot radius included: each obstacle's own margin when the policy gives one."""
    obstacle_distance: float = math.inf
    """m, from the robot's disc to the nearest *detected* obstacle (the robot's map, not
    the truth), or to the bounds' edges when they are nearer (< 0: overlap; inf: none):
    what the controller's keep-off acts on."""
    obstacle_direction: tuple[float, float] = (0.0, 0.0)
    """Unit vector from that obstacle's nearest point to the robot (zero when none, or
    when the robot's centre is inside it); for the bounds, the way back inside."""
    ahead_distance: float = math.inf
    """m the robot's disc travels along its velocity before it meets a detected obstacle
    or the bounds' edges (inf: none within ``look_ahead``, or at rest; 0: overlapping one
    already): the obstacle the robot heads for, which need not be the nearest (Nav2's
    collision monitor looks along the velocity in the same way)."""
    ahead_direction: tuple[float, float] = (0.0, 0.0)
    """Unit normal, toward the robot, of that obstacle's boundary where the disc meets it
    (zero when there is none)."""


class SafetyMonitor:
    """Running maximum of D_rob, the margin obstacles are grown by, the clearance to the map.

    Parameters
    ----------
    config : SafetyConfig
    """

    def __init__(self, config: SafetyConfig) -> None:
        self.config = config
        self.d_rob = 0.0
        self.d_rob_max = 0.0
        self.published_margin: float | None = None
        self.collided = False
        self._detected: Obstacles = []
        self._detected_stamp: int | None = None
        self._detected_rings: list[np.ndarray] = []
        self._detected_set = PolygonSet([])
        self._swept = PolygonSet([])
        """The detected obstacles grown by the robot radius: the robot's centre meets one
        where its disc meets the obstacle."""
        self._published = PolygonSet([])
        self._augmented_stamp = 0
        self._policy_margin: float | None = None
        self._local: Callable[[str, np.ndarray], float] | None = None
        self._published_local: dict[str, float] = {}
        self._grown_swept = GrownCache()
        self._grown_augmented = GrownCache()

    @property
    def swept(self) -> PolygonSet:
        """The detected obstacles grown by the robot radius, what the obstacle ahead is cast against.

        The robot's centre meets one where its disc meets the obstacle.
        """
        return self._swept

    @property
    def grown(self) -> int:
        """Obstacles grown afresh so far, by the robot radius and by their margins."""
        return self._grown_swept.grown + self._grown_augmented.grown

    @property
    def margin(self) -> float:
        """Current growth (m): max D_rob (or the margin policy's) + robot radius."""
        base = self.d_rob_max if self._policy_margin is None else self._policy_margin
        return base + self.config.robot_radius

    def follow(self, d_rob: float, d_rob_max: float, margin: float) -> bool:
        """Take the margin from a margin policy (:mod:`rrtq_planner.margins`) at this step.

        True when the margin has moved, up or down, by the growth threshold since the last
        publication: a margin that shrinks gives back the space it took (the planner
        restores the edges the smaller obstacles no longer block).
        """
        self.d_rob, self.d_rob_max, self._policy_margin = d_rob, d_rob_max, margin
        return (self.published_margin is None or abs(self.margin - self.published_margin)
                >= self.config.growth_threshold)

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
        (Inside the detected obstacle grown by the robot radius is a collision, not this case.)
        """
        self.published_margin = self.margin
        self._published_local = self._local_margins(obstacles)
        items = []
        for oid, poly in obstacles:
            margin = self._published_local.get(oid, self.margin)
            if position is not None:
                gap = float(shapely.Polygon(poly).distance(shapely.Point(
                    np.asarray(position, dtype=float)[:2])))
                margin = min(margin, max(gap - KEEP_OUT, 0.0))
            items.append((oid, poly, margin))
        grown = self._grown_augmented.grow(items)
        return [(oid, ring) for (oid, _, _), ring in zip(items, grown, strict=True)]

    def _local_margins(self, obstacles: Sequence[tuple[str, np.ndarray]]) -> dict[str, float]:
        """Per obstacle, the policy's margin by where it is + robot radius (none: empty)."""
        if self._local is None:
            return {}
        return {oid: self._local(oid, poly) + self.config.robot_radius for oid, poly in obstacles}

    def _local_moved(self) -> bool:
        """Whether an obstacle's own margin moved by the growth threshold since published."""
        now = self._local_margins(self._detected)
        if now.keys() != self._published_local.keys():
            return True
        return any(abs(m - self._published_local[oid]) >= self.config.growth_threshold
                   for oid, m in now.items())

    def step(self, stamp_ns: int, position: npt.ArrayLike, detected: OnChange[Obstacles] | None,
             leg: Leg | None, policy: tuple[float, float, float] | None = None,
             local: Callable[[str, np.ndarray], float] | None = None,
             velocity: npt.ArrayLike | None = None) -> SafetyStep:
        """One step of the safety node (RRT-QX §5).

        Measure D_rob on the current leg; republish the augmented set when the margin has
        grown, the detected set changed or a grown obstacle would swallow the robot;
        measure the clearance to the detected obstacles.

        Parameters
        ----------
        stamp_ns : int
            The step, ns of sim time.
        position : array_like, shape (2,)
            The robot, m.
        detected : OnChange, optional
            The robot's map (id, polygon) as last published (None: none yet).
        leg : Leg, optional
            The controller's leg of the step before (None: none yet).
        policy : (d_rob, d_rob_max, margin), optional
            m: a margin policy's answer at this step (:meth:`follow`); None: the running
            maximum of D_rob on ``leg`` (the paper's margin).
        local : callable, optional
            (id, polygon) -> m: the policy's margin of each obstacle by where it is
            (learned_bound, docs/margins.md §5.1); the augmented set is republished when one
            of them has moved by the growth threshold. None: every obstacle is grown by the
            margin.
        velocity : array_like, shape (2,), optional
            The robot's, m/s, for the obstacle ahead (None: none is looked for).
        """
        p = np.asarray(position, dtype=float)[:2]
        changed = detected is not None and detected.stamp_ns != self._detected_stamp
        if detected is not None and changed:
            self._detected_stamp = detected.stamp_ns
            self._detected = detected.read()
            self._detected_rings = [poly for _, poly in self._detected]
            self._detected_set = PolygonSet(self._detected_rings)
            self._swept = PolygonSet(self._grown_swept.grow(
                [(oid, poly, self.config.robot_radius) for oid, poly in self._detected]))
        grown = False
        if policy is not None:
            grown = self.follow(*policy)
            if local is not None or self._local is not None:
                self._local = local
                grown = self._local_moved() if local is not None else True
        elif leg is not None and leg.d0 > 0.0:
            grown = self.update(leg.start, leg.target, p)
        swallowed = self._published.nearest(p)[0] < 0.0
        augmented = None
        if changed or grown or swallowed or self.published_margin is None:
            self._augmented_stamp = stamp_ns
            augmented = self.augmented(self._detected, p)
            self._published = PolygonSet([poly for _, poly in augmented])
        near, direction, index = _nearest(p, self._detected_set, self._detected_rings,
                                          self.config.robot_radius)
        nearest = self._detected[index][0] if index >= 0 else ''
        new_collision = near < 0.0 and not self.collided
        self.collided = self.collided or new_collision
        ahead, normal = (math.inf, (0.0, 0.0)) if velocity is None else obstacle_ahead(
            p, velocity, self._swept, self.config.look_ahead)
        if self.config.bounds is not None:
            # The boundary is an obstacle too, known from the start (rrtq_planner.bounds).
            wall, inward = wall_distance(p, self.config.bounds, self.config.robot_radius)
            if wall < near:
                near, direction = wall, inward
            if velocity is not None:
                reach, facing = wall_ahead(p, velocity, self.config.bounds,
                                           self.config.robot_radius, self.config.look_ahead)
                if reach < ahead:
                    ahead, normal = reach, facing
        return SafetyStep(
            augmented=augmented, augmented_stamp_ns=self._augmented_stamp, d_rob=self.d_rob,
            d_rob_max=self.d_rob_max, margin=self.margin, clearance=float(near),
            nearest=nearest, collision=self.collided, new_collision=new_collision,
            leg_index=leg.index if leg is not None and leg.d0 > 0.0 else 0,
            local_margins=dict(self._published_local), obstacle_distance=near,
            obstacle_direction=direction, ahead_distance=ahead, ahead_direction=normal)


def clearance(position: npt.ArrayLike, polygons: PolygonSet | Sequence[np.ndarray],
              robot_radius: float) -> tuple[float, int]:
    """Distance (m) from the robot's disc to the nearest polygon (< 0 inside) and its index.

    (inf, -1) when there are no polygons. Give a :class:`PolygonSet` when the same
    polygons are asked about at every step.
    """
    shapes = polygons if isinstance(polygons, PolygonSet) else PolygonSet(polygons)
    value, index = shapes.nearest(np.asarray(position, dtype=float)[:2])
    return value - robot_radius, index


def obstacle_ahead(position: npt.ArrayLike, velocity: npt.ArrayLike, swept: PolygonSet,
                   look_ahead: float) -> tuple[float, tuple[float, float]]:
    """How far (m) the robot's disc moves along ``velocity`` before it meets an obstacle.

    ``swept`` holds the obstacles grown by the robot radius, so the disc meets one where its
    centre, moving along the ray, crosses a grown boundary. Returns that distance and the
    boundary's unit normal toward the robot; (inf, (0, 0)) at rest or with nothing within
    ``look_ahead``; (0, (0, 0)) when the centre is inside a grown obstacle already (the
    disc overlaps it: the nearest obstacle is what answers that).
    """
    p = np.asarray(position, dtype=float)[:2]
    v = np.asarray(velocity, dtype=float)[:2]
    if look_ahead <= 0.0 or len(swept) == 0 or not float(np.hypot(*v)) > 1e-9:
        return math.inf, (0.0, 0.0)
    if swept.nearest(p)[0] <= 0.0:
        return 0.0, (0.0, 0.0)
    distance, _, normal = swept.cast(p, v, look_ahead)
    return distance, normal


def nearest_obstacle(position: npt.ArrayLike, polygons: PolygonSet,
                     rings: Sequence[np.ndarray],
                     robot_radius: float) -> tuple[float, tuple[float, float]]:
    """The robot disc's distance (m) to the nearest polygon, and the unit vector to the robot.

    ``polygons`` is the :class:`PolygonSet` of ``rings`` (the same polygons, in order).
    The direction points from the polygon's nearest boundary point to the robot's centre
    (away from the obstacle); (0, 0) when there is no polygon or the centre is inside one.
    """
    distance, direction, _ = _nearest(position, polygons, rings, robot_radius)
    return distance, direction


def _nearest(position: npt.ArrayLike, polygons: PolygonSet, rings: Sequence[np.ndarray],
             robot_radius: float) -> tuple[float, tuple[float, float], int]:
    """:func:`nearest_obstacle`, and the index of that polygon (-1: none)."""
    p = np.asarray(position, dtype=float)[:2]
    value, index = polygons.nearest(p)
    if index < 0:
        return math.inf, (0.0, 0.0), -1
    if value <= 0.0:
        return value - robot_radius, (0.0, 0.0), index
    ring = shapely.LinearRing(rings[index])
    closest = ring.interpolate(ring.project(shapely.Point(p)))
    away = p - np.array([closest.x, closest.y])
    norm = float(np.hypot(*away))
    direction = (0.0, 0.0) if norm < 1e-12 else (float(away[0] / norm), float(away[1] / norm))
    return value - robot_radius, direction, index
