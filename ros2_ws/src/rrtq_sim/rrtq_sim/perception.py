"""What the robot knows about the obstacles: truth versus map inside the sensing disc.

docs/design.md, Perception: at every step an existing obstacle that intersects the
perception disc becomes known (added once); a known obstacle that no longer exists is
removed when its location is inside the disc.  What exists is :class:`TrueObstacles`:
the scenario's timing, except that nothing appears on top of the robot.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from rrtq_sim.obstacles import disc_intersects_polygon, point_polygon_distance
from rrtq_sim.scenario import ObstacleSpec, Scenario

__all__ = ['ObstacleEvent', 'Perception', 'TrueObstacles']


class ObstacleEvent(enum.StrEnum):
    """A change to the robot's obstacle map."""

    DETECTED = 'detected'
    REMOVED = 'removed'


class TrueObstacles:
    """What physically exists, step by step: the scenario's timing, never on the robot.

    An obstacle exists from ``appear_at`` until ``vanish_at``, except that one due to
    appear during the run (``appear_at > 0``) while it is within ``clearance`` of the
    robot's disc is held back: it appears at the first later step at which the robot is
    clear of it, and not at all if its ``vanish_at`` comes first. Obstacles there at
    t = 0 are never held (the scenario loader keeps the start clear of them).

    The spawner, the safety node and the referee each keep one and feed it the same
    odometry, so they agree on the truth at every step.

    Parameters
    ----------
    obstacles : sequence of ObstacleSpec
        Ground truth, in scenario order.
    robot_radius : float
        m (>= 0).
    clearance : float
        Smallest gap between the robot's disc and an obstacle that appears, m (>= 0).
    """

    def __init__(self, obstacles: Sequence[ObstacleSpec], robot_radius: float = 0.0,
                 clearance: float = 0.0) -> None:
        for name, value in (('robot_radius', robot_radius), ('clearance', clearance)):
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be finite and >= 0, got {value!r}')
        self._specs = tuple(obstacles)
        self._reach = float(robot_radius) + float(clearance)
        self._existing = tuple(spec for spec in self._specs if spec.exists(0.0))
        self._appeared = {spec.id: 0.0 for spec in self._existing}
        self._held: frozenset[str] = frozenset()

    @classmethod
    def for_scenario(cls, scenario: Scenario) -> TrueObstacles:
        """The truth of a scenario: its obstacles, robot radius and ``appear_clearance``."""
        return cls(scenario.obstacles, scenario.robot_radius, scenario.appear_clearance)

    @property
    def existing(self) -> tuple[ObstacleSpec, ...]:
        """The obstacles that existed at the last update (before any: at t = 0)."""
        return self._existing

    @property
    def held(self) -> frozenset[str]:
        """Ids due to exist at the last update but held back because the robot was near."""
        return self._held

    @property
    def appeared_at(self) -> dict[str, float]:
        """Time (s) each obstacle came to exist so far (later than its appear_at if held)."""
        return dict(self._appeared)

    def update(self, position: npt.ArrayLike, t: float) -> tuple[ObstacleSpec, ...]:
        """Advance to time ``t`` (s) with the robot at ``position`` (m).

        Returns
        -------
        tuple of ObstacleSpec
            The obstacles that exist at ``t``, in scenario order.
        """
        p = np.asarray(position, dtype=float).reshape(-1)
        if p.shape != (2,):
            raise ValueError(f'position must have shape (2,), got {np.shape(position)}')
        held = []
        for spec in self._specs:
            if spec.id in self._appeared or not spec.exists(t):
                continue
            if spec.appear_at > 0.0 and point_polygon_distance(p, spec.polygon) <= self._reach:
                held.append(spec.id)
            else:
                self._appeared[spec.id] = t
        self._held = frozenset(held)
        self._existing = tuple(spec for spec in self._specs if spec.id in self._appeared
                               and t < spec.vanish_at)
        return self._existing


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
