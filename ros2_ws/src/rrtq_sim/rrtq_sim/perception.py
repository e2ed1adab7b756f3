"""What the robot knows about the obstacles: truth versus map inside the sensing disc.

DESIGN.md, Perception: at every step an existing obstacle that intersects the
perception disc becomes known (added once); a known obstacle that no longer exists is
removed when its location is inside the disc.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from rrtq_sim.obstacles import disc_intersects_polygon
from rrtq_sim.scenario import ObstacleSpec

__all__ = ['ObstacleEvent', 'Perception']


class ObstacleEvent(enum.StrEnum):
    """A change to the robot's obstacle map."""

    DETECTED = 'detected'
    REMOVED = 'removed'


class Perception:
    """Omnidirectional range-limited obstacle sensing.

    Parameters
    ----------
    obstacles : sequence of ObstacleSpec
        Ground truth, in scenario order (events follow this order).
    radius : float
        Perception radius, m (> 0).
    """

    def __init__(self, obstacles: Sequence[ObstacleSpec], radius: float) -> None:
        if not (np.isfinite(radius) and radius > 0.0):
            raise ValueError(f'radius must be finite and > 0, got {radius!r}')
        ids = [spec.id for spec in obstacles]
        if len(set(ids)) != len(ids):
            raise ValueError('obstacle ids must be unique')
        self._specs = tuple(obstacles)
        self._radius = float(radius)
        self._known = {spec.id for spec in self._specs if spec.known}
        # Axis-aligned boxes let most obstacles be rejected without the exact
        # disc-polygon test (the scenario may hold hundreds of Otte polygons).
        self._lo = np.array([spec.polygon.min(axis=0) for spec in self._specs]).reshape(-1, 2)
        self._hi = np.array([spec.polygon.max(axis=0) for spec in self._specs]).reshape(-1, 2)

    @property
    def radius(self) -> float:
        """Perception radius, m."""
        return self._radius

    @property
    def obstacles(self) -> tuple[ObstacleSpec, ...]:
        """Ground truth, in scenario order."""
        return self._specs

    @property
    def known_ids(self) -> frozenset[str]:
        """Ids currently in the robot's map."""
        return frozenset(self._known)

    def known_obstacles(self) -> list[ObstacleSpec]:
        """The robot's map, in scenario order."""
        return [spec for spec in self._specs if spec.id in self._known]

    @staticmethod
    def exists(spec: ObstacleSpec, t: float) -> bool:
        """True when the obstacle exists at ``t`` (s): ``appear_at <= t < vanish_at``."""
        return spec.appear_at <= t < spec.vanish_at

    def step(self, position: npt.ArrayLike, t: float) -> list[tuple[ObstacleEvent, str]]:
        """Update the map from the sensing disc at ``position`` (m) and time ``t`` (s).

        Returns
        -------
        list of (ObstacleEvent, str)
            The map changes of this step, in scenario order; at most one per obstacle.
        """
        p = np.asarray(position, dtype=float).reshape(-1)
        if p.shape != (2,):
            raise ValueError(f'position must have shape (2,), got {np.shape(position)}')
        if not self._specs:
            return []
        r = self._radius
        near = np.all((self._lo - r <= p) & (p <= self._hi + r), axis=1)
        events: list[tuple[ObstacleEvent, str]] = []
        for index in np.flatnonzero(near):
            spec = self._specs[index]
            known = spec.id in self._known
            exists = self.exists(spec, t)
            if known == exists:
                continue  # the map already agrees with the truth
            if not disc_intersects_polygon(p, r, spec.polygon):
                continue
            if exists:
                self._known.add(spec.id)
                events.append((ObstacleEvent.DETECTED, spec.id))
            else:
                self._known.discard(spec.id)
                events.append((ObstacleEvent.REMOVED, spec.id))
        return events
