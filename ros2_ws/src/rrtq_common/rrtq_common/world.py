"""The world of a scenario: its obstacles as they physically exist, and where the robot is.

The spawner, the safety node and the referee each read the world from the scenario file
(:func:`rrtq_common.world_yaml.load_world`) and keep a :class:`TrueObstacles` fed with the
same odometry, so they agree on the truth at every step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.geometry import point_polygon_distance
from rrtq_common.scan import PerceptionConfig
from rrtq_common.settings import setting

__all__ = ['ObstacleSpec', 'World', 'TrueObstacles']


@dataclass(frozen=True, eq=False)
class ObstacleSpec:
    """One ground-truth obstacle.

    Attributes
    ----------
    id : str
        Unique name.
    polygon : numpy.ndarray, shape (k, 2)
        Vertices, m (circles arrive as circumscribing polygons).
    appear_at : float
        Time it starts to physically exist, s.
    vanish_at : float
        Time it stops existing, s (``inf``: never; ``== appear_at``: never exists).
    known : bool
        In the robot's map at t = 0.
    """

    id: str
    polygon: np.ndarray
    appear_at: float = 0.0
    vanish_at: float = math.inf
    known: bool = False

    def exists(self, t: float) -> bool:
        """True when it physically exists at ``t`` (s): ``appear_at <= t < vanish_at``."""
        return self.appear_at <= t < self.vanish_at

    @property
    def ever_exists(self) -> bool:
        """True when it physically exists at some time."""
        return self.appear_at < self.vanish_at


@dataclass(frozen=True, eq=False, kw_only=True)
class World:
    """Where the robot runs: the region, its start and goal, what it senses, the obstacles.

    Attributes
    ----------
    bounds : ((float, float), (float, float))
        ((x_min, x_max), (y_min, y_max)), m.
    start, goal : numpy.ndarray, shape (2,)
        Positions, m; the robot starts at rest.
    perception_radius : float
        m.
    robot_radius : float
        m; every obstacle is grown by it.
    appear_clearance : float
        m; an obstacle due to appear during the run while it is within this distance of
        the robot's disc is held back until it is not (:class:`TrueObstacles`).
    obstacles : tuple of ObstacleSpec
        Ground truth, in file order.
    perception : PerceptionConfig
        Where the robot's map comes from (``range_max`` set: the file's, else
        ``perception_radius``).
    """

    bounds: tuple[tuple[float, float], tuple[float, float]]
    start: np.ndarray
    goal: np.ndarray
    perception_radius: float = setting(8.0, unit='m', low=0.0, low_open=True,
                                       doc='radius of the omnidirectional perception')
    robot_radius: float = setting(0.0, unit='m', low=0.0,
                                  doc='radius of the robot disc; every obstacle is grown by it')
    appear_clearance: float = setting(1.0, unit='m', low=0.0,
                                      doc='an obstacle due to appear within this distance '
                                      "of the robot's disc is held back until it is not")
    obstacles: tuple[ObstacleSpec, ...] = ()
    perception: PerceptionConfig = PerceptionConfig()


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
    def for_scenario(cls, world: World) -> TrueObstacles:
        """The truth of a scenario's world: its obstacles, robot radius, ``appear_clearance``."""
        return cls(world.obstacles, world.robot_radius, world.appear_clearance)

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
