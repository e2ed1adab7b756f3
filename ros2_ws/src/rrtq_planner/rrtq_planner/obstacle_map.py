"""The robot's obstacle map built from 360° laser scans (no rclpy).

Each scan, placed in the map at the odometry's position (``base_link`` is axis-aligned with
``map``, :mod:`rrtq_common.scan`), goes through three steps:

1. ``remove_freed``: an obstacle whose observed returns (the convex hull of the returns it
   was built from, its *core*) are crossed by at least ``free_beams`` beams of the scan
   that end beyond them, while no return of the scan falls inside its polygon, is removed:
   that space is free now.
2. ``segment``: consecutive returns (circularly) form a cluster until the gap between two
   neighbours exceeds the adaptive breakpoint distance (Borges & Aldon 2004, eq. 7)
   ``D(r) = r sin Δθ / sin(λ - Δθ) + 3 √2 σ``: the spacing of two returns at range r on a
   surface seen at an incidence of λ from the beam, plus three standard deviations of the
   difference of two noisy ranges.
3. ``associate`` and ``grow``: a cluster whose polygon meets an obstacle's joins it (several:
   they merge into the oldest, the others are removed); its returns that lie outside the
   obstacle's polygon grow it: core ← hull(core ∪ returns), polygon ← hull(polygon ∪
   (core ⊕ b)). A cluster that meets nothing is a new obstacle with a new id. The polygon
   only ever grows, so every return ever associated with an obstacle stays inside it.

The buffer ``b = 3σ + g`` with ``g = 2 r sin(Δθ / 2)`` the gap between two adjacent beams at
the cluster's farthest range r (docs/design.md, Perception): the surface between two returns
is at most 3σ in front of them (noise); at a cluster's end the obstacle may reach sideways
up to the next beam (at most g); and a convex corner that points at the robot between two
returns sticks out of the chord by at most ``(g / 2) / tan(α / 2)``, which g covers for
interior angles α >= 2 atan(1/2) ≈ 53°. What the scan cannot see (the back side of an
obstacle) is not in the map until it is seen: the polygon is the hull of what was seen.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry.base import BaseGeometry

from rrtq_common.scan import PerceptionConfig, beam_directions
from rrtq_common.settings import like, setting

__all__ = ['MapEvent', 'MapperConfig', 'MapObstacle', 'MapUpdate', 'ObstacleMap',
           'breakpoint_distance', 'segment']


class MapEvent(enum.StrEnum):
    """A change to the robot's obstacle map."""

    DETECTED = 'detected'
    GROWN = 'grown'
    REMOVED = 'removed'


@dataclass(frozen=True)
class MapperConfig:
    """The obstacle mapper: the scanner it reads, and how it clusters and forgets."""

    beams: int = like(PerceptionConfig, 'beams')
    range_max: float = setting(8.0, unit='m', low=0.0, low_open=True,
                               doc="the scan's maximum range")
    noise_std: float = like(PerceptionConfig, 'noise_std')
    rate: float = like(PerceptionConfig, 'rate')
    incidence_deg: float = setting(10.0, unit='deg', low=0.0, high=90.0, low_open=True,
                                   high_open=True,
                                   doc='λ: smallest angle between a beam and a surface whose '
                                   'returns stay one cluster')
    free_beams: int = setting(3, low=1, doc='beams of one scan crossing an obstacle\'s seen '
                              'returns that remove it')
    id_prefix: str = setting('scan', doc='ids of the map\'s obstacles: <prefix>_<n>')

    @property
    def angle_increment(self) -> float:
        """Angle between adjacent beams, rad."""
        return 2.0 * math.pi / self.beams

    def beam_gap(self, r: npt.ArrayLike) -> np.ndarray:
        """Distance between adjacent beams at range ``r`` (m): ``2 r sin(Δθ / 2)``."""
        return 2.0 * np.asarray(r, dtype=float) * math.sin(self.angle_increment / 2.0)

    def buffer(self, r: float) -> float:
        """Buffer of a cluster whose farthest return is at ``r`` (m): ``3σ + gap(r)``."""
        return 3.0 * self.noise_std + float(self.beam_gap(r))


def breakpoint_distance(r: npt.ArrayLike, config: MapperConfig) -> np.ndarray:
    """Largest gap (m) between neighbouring returns at range ``r`` (m) within one cluster.

    ``D(r) = r sin Δθ / sin(λ - Δθ) + 3 √2 σ`` (adaptive breakpoint detector, Borges &
    Aldon 2004, eq. 7, with the noise of both ranges); ``λ <= Δθ``: no limit from the angle.
    """
    dtheta = config.angle_increment
    lam = math.radians(config.incidence_deg)
    rr = np.asarray(r, dtype=float)
    angular = rr * math.sin(dtheta) / math.sin(lam - dtheta) if lam > dtheta else np.inf * rr
    return angular + 3.0 * math.sqrt(2.0) * config.noise_std


def segment(points: np.ndarray, ranges: np.ndarray, config: MapperConfig) -> list[np.ndarray]:
    """Clusters of consecutive returns (beam indices), the scan taken as circular.

    Parameters
    ----------
    points : numpy.ndarray, shape (N, 2)
        The returns in the map, m (rows of beams without a return are ignored).
    ranges : numpy.ndarray, shape (N,)
        The ranges, m; not finite or above ``range_max``: no return.

    Returns
    -------
    list of numpy.ndarray
        Beam indices of each cluster, in scan order.
    """
    n = len(ranges)
    valid = np.isfinite(ranges) & (ranges <= config.range_max)
    if n == 0 or not valid.any():
        return []
    nxt = np.roll(np.arange(n), -1)
    gap = np.linalg.norm(points[nxt] - points, axis=1)
    limit = breakpoint_distance(np.maximum(np.where(valid, ranges, 0.0),
                                           np.where(valid[nxt], ranges[nxt], 0.0)), config)
    linked = valid & valid[nxt] & (np.where(valid & valid[nxt], gap, np.inf) <= limit)
    if linked.all():
        return [np.arange(n)]
    start = (int(np.argmin(linked)) + 1) % n          # just after a break
    order = np.roll(np.arange(n), -start)
    ends = np.flatnonzero(~linked[order]) + 1         # a cluster ends where the link breaks
    clusters = np.split(order, ends[:-1])
    return [c for c in clusters if valid[c[0]]]


def _hull(points: np.ndarray) -> BaseGeometry:
    return shapely.MultiPoint(points).convex_hull


def _vertices(polygon: BaseGeometry) -> np.ndarray:
    """Counter-clockwise vertices of a polygon (the last not repeated)."""
    if not isinstance(polygon, shapely.Polygon):
        raise TypeError(f'expected a polygon, got {polygon.geom_type}')
    oriented = shapely.geometry.polygon.orient(polygon, 1.0)
    return np.asarray(oriented.exterior.coords, dtype=float)[:-1]


@dataclass(frozen=True)
class MapObstacle:
    """One obstacle of the map.

    Attributes
    ----------
    id : str
        Stable while the obstacle is in the map.
    core : numpy.ndarray, shape (k, 2)
        Vertices of the convex hull of the returns it grew from, m.
    buffer : float
        m; the largest buffer of its clusters.
    polygon : numpy.ndarray, shape (m, 2)
        What is published: convex, counter-clockwise, m.
    """

    id: str
    core: np.ndarray
    buffer: float
    polygon: np.ndarray


@dataclass(frozen=True)
class MapUpdate:
    """What one scan changed."""

    events: list[tuple[MapEvent, str]]
    """The changes, in the order they happened (removals first)."""
    clusters: int
    """Clusters in the scan."""


class ObstacleMap:
    """Obstacles from scans: clustered, associated by overlap, grown, removed when seen through.

    Parameters
    ----------
    config : MapperConfig
    """

    def __init__(self, config: MapperConfig) -> None:
        self.config = config
        self.directions = beam_directions(config.beams)
        self._obstacles: dict[str, MapObstacle] = {}
        self._shapes: dict[str, BaseGeometry] = {}
        self._count = 0

    @property
    def obstacles(self) -> list[MapObstacle]:
        """The map, oldest first."""
        return list(self._obstacles.values())

    def integrate(self, position: npt.ArrayLike, ranges: npt.ArrayLike) -> MapUpdate:
        """Update the map with one scan taken at ``position`` (m, map frame).

        Parameters
        ----------
        position : array_like, shape (2,)
            Where the scan was taken (the odometry's position at its stamp), m.
        ranges : array_like, shape (beams,)
            The scan's ranges, m (``inf``: no return).
        """
        p = np.asarray(position, dtype=float).reshape(2)
        r = np.asarray(ranges, dtype=float).reshape(-1)
        if r.shape != (self.config.beams,):
            raise ValueError(f'expected {self.config.beams} ranges, got {r.shape}')
        hit = np.isfinite(r) & (r <= self.config.range_max)
        points = p + np.where(hit, r, 0.0)[:, None] * self.directions
        events = self.remove_freed(p, r, points[hit])
        clusters = segment(points, r, self.config)
        for cluster in clusters:
            events.extend(self.associate(points[cluster], float(r[cluster].max())))
        return MapUpdate(events, len(clusters))

    def remove_freed(self, position: np.ndarray, ranges: np.ndarray,
                     returns: np.ndarray) -> list[tuple[MapEvent, str]]:
        """Remove the obstacles the scan sees through (free-space evidence).

        A beam's free segment runs from ``position`` to ``tol`` short of its return
        (``range_max`` without one), ``tol = 6σ + gap(r)``: a return and a core vertex may
        each be 3σ off the surface.
        """
        cfg = self.config
        if not self._obstacles:
            return []
        hit = np.isfinite(ranges) & (ranges <= cfg.range_max)
        r = np.where(hit, ranges, 0.0)
        reach = np.where(hit, r - 6.0 * cfg.noise_std - cfg.beam_gap(r), cfg.range_max)
        reach = np.maximum(reach, 0.0)
        ends = position + reach[:, None] * self.directions
        lines = shapely.linestrings(np.stack([np.broadcast_to(position, ends.shape), ends],
                                             axis=1))
        events: list[tuple[MapEvent, str]] = []
        for ident, obstacle in list(self._obstacles.items()):
            crossing = int(np.count_nonzero(shapely.intersects(lines, _hull(obstacle.core))))
            if crossing < cfg.free_beams:
                continue
            if len(returns) and shapely.intersects_xy(self._shapes[ident], returns[:, 0],
                                                      returns[:, 1]).any():
                continue  # part of it is still seen: keep it whole
            self._drop(ident)
            events.append((MapEvent.REMOVED, ident))
        return events

    def associate(self, points: np.ndarray, far: float) -> list[tuple[MapEvent, str]]:
        """Join a cluster's returns (m) to the obstacles they overlap, or start a new one.

        ``far``: the cluster's largest range, m (sets its buffer).
        """
        b = self.config.buffer(far)
        fresh = _hull(points).buffer(b, cap_style='square', join_style='mitre', mitre_limit=2.0)
        touched = [ident for ident, shape in self._shapes.items() if shape.intersects(fresh)]
        if not touched:
            self._count += 1
            ident = f'{self.config.id_prefix}_{self._count}'
            self._store(ident, _core_vertices(_hull(points), points), b, fresh)
            return [(MapEvent.DETECTED, ident)]
        keep, others = touched[0], touched[1:]
        events = [(MapEvent.REMOVED, ident) for ident in others]
        cores = [self._obstacles[ident].core for ident in touched]
        shapes = [self._shapes[ident] for ident in touched]
        buffer = max([b] + [self._obstacles[ident].buffer for ident in touched])
        outside = ~shapely.intersects_xy(self._shapes[keep], points[:, 0], points[:, 1])
        for ident in others:
            self._drop(ident)
        if not others and not outside.any():
            return events  # nothing new: the map stays as published
        core_points = np.concatenate(cores + [points])
        core = _hull(core_points)
        grown = core.buffer(buffer, cap_style='square', join_style='mitre', mitre_limit=2.0)
        polygon = shapely.convex_hull(shapely.union_all(shapes + [grown]))
        self._store(keep, _core_vertices(core, core_points), buffer, polygon)
        return events + [(MapEvent.GROWN, keep)]

    def _store(self, ident: str, core: np.ndarray, buffer: float,
               polygon: BaseGeometry) -> None:
        self._obstacles[ident] = MapObstacle(ident, np.asarray(core, dtype=float), buffer,
                                             _vertices(polygon))
        self._shapes[ident] = polygon

    def _drop(self, ident: str) -> None:
        del self._obstacles[ident]
        del self._shapes[ident]


def _core_vertices(core: BaseGeometry, points: np.ndarray) -> np.ndarray:
    """The vertices of a hull (a polygon, or for collinear points the points' extremes)."""
    if core.geom_type == 'Polygon':
        return _vertices(core)
    return np.asarray(shapely.get_coordinates(core), dtype=float).reshape(-1, 2) \
        if not core.is_empty else points[:1]
