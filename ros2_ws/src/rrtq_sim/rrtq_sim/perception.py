"""What the robot knows about the obstacles: truth versus map inside the sensing disc.

docs/design.md, Perception: at every step an existing obstacle that intersects the
perception disc becomes known (added once); a known obstacle that no longer exists is
removed when its location is inside the disc.  What exists is
:class:`rrtq_common.world.TrueObstacles`: the scenario's timing, except that nothing
appears on top of the robot.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.geometry import disc_intersects_polygon
from rrtq_common.polygon_set import LivePolygons
from rrtq_common.world import ObstacleSpec, TrueObstacles

__all__ = ['ObstacleEvent', 'Observation', 'Perception']


class ObstacleEvent(enum.StrEnum):
    """A change to the robot's obstacle map."""

    DETECTED = 'detected'
    REMOVED = 'removed'


@dataclass(frozen=True)
class Observation:
    """One step of :meth:`Perception.observe`: what the spawner node publishes and logs."""

    events: list[tuple[ObstacleEvent, str]]
    """The map changes of this step, in scenario order."""
    held: list[str]
    """Ids held back from appearing since this step (the robot is within their clearance)."""
    truth: tuple[ObstacleSpec, ...] | None
    """What exists, when it changed at this step (None: unchanged)."""
    in_range: int
    """Existing obstacles that meet the perception disc."""


class Perception:
    """Omnidirectional range-limited obstacle sensing.

    Parameters
    ----------
    obstacles : sequence of ObstacleSpec
        Ground truth, in scenario order (events follow this order).
    radius : float
        Perception radius, m (> 0).
    truth : TrueObstacles, optional
        What exists, updated by :meth:`step` (default: the obstacles' own timing, no
        robot radius, no clearance).
    """

    def __init__(self, obstacles: Sequence[ObstacleSpec], radius: float,
                 truth: TrueObstacles | None = None) -> None:
        if not (np.isfinite(radius) and radius > 0.0):
            raise ValueError(f'radius must be finite and > 0, got {radius!r}')
        ids = [spec.id for spec in obstacles]
        if len(set(ids)) != len(ids):
            raise ValueError('obstacle ids must be unique')
        self._specs = tuple(obstacles)
        self.truth = truth if truth is not None else TrueObstacles(self._specs)
        self._radius = float(radius)
        self._known = {spec.id for spec in self._specs if spec.known}
        # Axis-aligned boxes let most obstacles be rejected without the exact
        # disc-polygon test (the scenario may hold hundreds of Otte polygons).
        self._lo = np.array([spec.polygon.min(axis=0) for spec in self._specs]).reshape(-1, 2)
        self._hi = np.array([spec.polygon.max(axis=0) for spec in self._specs]).reshape(-1, 2)
        self._held: frozenset[str] = frozenset()
        self._reported: list[str] | None = None
        self._existing_shapes = LivePolygons()

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

    def step(self, position: npt.ArrayLike, t: float) -> list[tuple[ObstacleEvent, str]]:
        """Update the truth, then the map from the sensing disc at ``position`` (m), ``t`` (s).

        Returns
        -------
        list of (ObstacleEvent, str)
            The map changes of this step, in scenario order; at most one per obstacle.
        """
        p = np.asarray(position, dtype=float).reshape(-1)
        if p.shape != (2,):
            raise ValueError(f'position must have shape (2,), got {np.shape(position)}')
        existing = {spec.id for spec in self.truth.update(p, t)}
        if not self._specs:
            return []
        r = self._radius
        near = np.all((self._lo - r <= p) & (p <= self._hi + r), axis=1)
        events: list[tuple[ObstacleEvent, str]] = []
        for index in np.flatnonzero(near):
            spec = self._specs[index]
            known = spec.id in self._known
            exists = spec.id in existing
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

    def take_truth_change(self) -> tuple[ObstacleSpec, ...] | None:
        """What exists now if that differs from what this last returned (first call: it)."""
        existing = [spec.id for spec in self.truth.existing]
        if existing == self._reported:
            return None
        self._reported = existing
        return self.truth.existing

    def observe(self, position: npt.ArrayLike, t: float) -> Observation:
        """:meth:`step`, with what changed in the truth and what the disc meets."""
        events = self.step(position, t)
        held = sorted(self.truth.held - self._held)
        self._held = self.truth.held
        truth = self.take_truth_change()
        in_range = len(self._existing_shapes.update(self.truth.existing).within(
            np.asarray(position, dtype=float)[:2], self._radius))
        return Observation(events, held, truth, in_range)
