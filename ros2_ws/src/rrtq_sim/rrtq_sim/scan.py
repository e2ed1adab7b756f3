"""A simulated 360° laser scanner: rays cast against the true obstacles (no rclpy).

Every beam is intersected with every edge of every obstacle near enough at once (one
numpy broadcast over beams × edges); a beam's range is its nearest hit, ``+inf`` when it
meets nothing within ``range_max`` (REP-117). Gaussian range noise (seeded) is added to
the returns; a noisy return past ``range_max`` reads ``+inf`` too, one below 0 reads 0.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.scan import PerceptionConfig, beam_directions
from rrtq_common.settings import setting
from rrtq_common.world import ObstacleSpec
from rrtq_sim.plant import PlantModel

__all__ = ['cast_rays', 'RayCaster', 'polygon_rays', 'ScanWorld', 'LaserScanner']

RayCaster = Callable[[npt.ArrayLike, np.ndarray, Sequence[ObstacleSpec], float], np.ndarray]
"""``(origin, directions (N, 2), existing obstacles, range_max) -> ranges (N,)``, m;
``+inf`` for a ray that meets nothing within ``range_max``."""


def _edges(polygons: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Start points and edge vectors of all the polygons' edges, each (E, 2)."""
    if not polygons:
        empty = np.zeros((0, 2))
        return empty, empty
    starts = np.concatenate([np.asarray(p, dtype=float) for p in polygons])
    ends = np.concatenate([np.roll(np.asarray(p, dtype=float), -1, axis=0) for p in polygons])
    return starts, ends - starts


def cast_rays(origin: npt.ArrayLike, directions: np.ndarray,
              polygons: Sequence[np.ndarray], range_max: float) -> np.ndarray:
    """Distance along each ray from ``origin`` to the first polygon edge it meets.

    Ray ``o + t d`` meets edge ``a + s e`` where ``t = (w × e) / (d × e)`` and
    ``s = (w × d) / (d × e)`` with ``w = a - o``; a hit needs ``t >= 0`` and ``0 <= s <= 1``.
    Edges parallel to a ray (``d × e = 0``) are never hit: a ray grazing along an edge meets
    the edges at its ends.

    Parameters
    ----------
    origin : array_like, shape (2,)
        Where the rays start, m.
    directions : numpy.ndarray, shape (N, 2)
        Unit vectors of the rays.
    polygons : sequence of numpy.ndarray, each (k, 2)
        Closed polygons (last vertex not repeated), m.
    range_max : float
        Longest range, m.

    Returns
    -------
    numpy.ndarray, shape (N,)
        The ranges, m; ``+inf`` for a ray that meets nothing within ``range_max``.
    """
    o = np.asarray(origin, dtype=float).reshape(2)
    d = np.asarray(directions, dtype=float).reshape(-1, 2)
    a, e = _edges(polygons)
    ranges = np.full(len(d), np.inf)
    if len(a) == 0 or len(d) == 0:
        return ranges
    w = a - o                                                   # (E, 2)
    denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]   # d × e, (N, E)
    w_cross_e = w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]           # (E,)
    w_cross_d = w[None, :, 0] * d[:, None, 1] - w[None, :, 1] * d[:, None, 0]  # (N, E)
    parallel = np.abs(denom) < 1e-12
    safe = np.where(parallel, 1.0, denom)
    t = w_cross_e[None, :] / safe
    s = w_cross_d / safe
    hit = ~parallel & (t >= 0.0) & (s >= 0.0) & (s <= 1.0)
    t = np.where(hit, t, np.inf).min(axis=1)
    ranges[t <= range_max] = t[t <= range_max]
    return ranges


def polygon_rays(origin: npt.ArrayLike, directions: np.ndarray,
                 obstacles: Sequence[ObstacleSpec], range_max: float) -> np.ndarray:
    """:func:`cast_rays` against the obstacles whose bounding box comes within ``range_max``."""
    p = np.asarray(origin, dtype=float).reshape(2)
    r = float(range_max)
    near = [spec.polygon for spec in obstacles
            if np.all(spec.polygon.min(axis=0) - r <= p) and np.all(p <= spec.polygon.max(axis=0) + r)]
    return cast_rays(p, directions, near, r)


@dataclass(frozen=True)
class ScanWorld:
    """What the scanner casts its rays in: the plant's world (the plant section's keys)."""

    model: PlantModel = setting(PlantModel.ROVER, doc='plant family; mujoco: rays cast by '
                                'mj_multiRay in the MuJoCo model the plant steps')
    mjcf: str | None = setting(None, doc="mujoco: the user's MJCF file (none: the shipped "
                               'planar base)')


class LaserScanner:
    """The scanner of a scenario's ``perception:`` section, with its own noise generator.

    Parameters
    ----------
    config : PerceptionConfig
        Beams, ``range_max`` (must be set) and ``noise_std``.
    rng : numpy.random.Generator
        The noise's generator (seeded by the run: the same seed, the same scans).
    caster : RayCaster
        What casts the rays: :func:`polygon_rays` (the default) or the MuJoCo plant's
        :class:`rrtq_sim.mujoco_rays.MujocoRays`.
    """

    def __init__(self, config: PerceptionConfig, rng: np.random.Generator,
                 caster: RayCaster = polygon_rays) -> None:
        if config.range_max is None:
            raise ValueError('range_max must be set (the loader defaults it)')
        self.config = config
        self.range_max = float(config.range_max)
        self.directions = beam_directions(config.beams)
        self._rng = rng
        self._cast = caster

    def scan(self, position: npt.ArrayLike, obstacles: Sequence[ObstacleSpec]) -> np.ndarray:
        """The ranges (m) from ``position`` (m) among the existing ``obstacles``, noise in.

        ``+inf``: no return.
        """
        r = self.range_max
        ranges = self._cast(position, self.directions, obstacles, r)
        # One draw per beam on every scan, returns or not: the noise of a beam does not
        # depend on what the others see.
        noise = self._rng.normal(0.0, 1.0, len(ranges)) * self.config.noise_std
        if self.config.noise_std > 0.0:
            finite = np.isfinite(ranges)
            ranges[finite] = np.maximum(ranges[finite] + noise[finite], 0.0)
            ranges[ranges > r] = np.inf
        return ranges
