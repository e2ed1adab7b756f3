"""The guiding level as the planner node runs it: plan and obstacle sets in, a reference out.

Each planning cycle (each step in lock-step) :class:`GuidanceSession` takes the robot's
state, the planner's current waypoints and the augmented obstacle set, and answers the
reference trajectory the controller tracks (``/guidance/reference``). The desired path is
the robot's position followed by the RRT^X waypoints. A :class:`GuidanceTrack` (one
rollout of the integral curve) is kept while it stays valid: a new one is built when the
augmented set changed, or when the plan changed other than by dropping waypoints the robot
has passed (the planner's plan always starts at the robot's next waypoint). Without a path
the reference holds the robot's position at rest (``no_path``).
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.lockstep import OnChange

from .config import GuidanceConfig
from .curve import Reference
from .track import GuidanceTrack

__all__ = ['GuidanceSession', 'GuidanceOutput', 'ReferenceStatus']


class ReferenceStatus(enum.StrEnum):
    """What the reference follows (``/guidance/reference``'s ``status``)."""

    REACHED = 'reached'
    """A curve that reaches the goal."""
    LENGTH = 'length'
    """A curve cut before the goal (its length budget)."""
    STALLED = 'stalled'
    """A curve that stopped progressing along the path (a deadlock, reported)."""
    NO_PATH = 'no_path'
    """No desired path: the robot's position, held at rest."""


@dataclass(frozen=True)
class GuidanceOutput:
    """One cycle's reference and what it was built from."""

    reference: Reference
    status: ReferenceStatus
    rollout: int                  # rollouts of the integral curve so far
    obstacles_stamp_ns: int       # the augmented set the fields use
    plan_stamp_ns: int            # the plan whose path is the desired path


class GuidanceSession:
    """The guidance track of the current plan and obstacles, rebuilt when they change.

    Parameters
    ----------
    config : GuidanceConfig
    """

    def __init__(self, config: GuidanceConfig) -> None:
        self.config = config
        self.track: GuidanceTrack | None = None
        self._waypoints = np.zeros((0, 2))
        self._polygons: list[np.ndarray] = []
        self._obstacles_stamp: int | None = None
        self._plan_stamp = 0
        self._rollouts = 0          # of tracks already replaced

    @property
    def rollouts(self) -> int:
        """Rollouts of the integral curve so far, over every track."""
        return self._rollouts + (self.track.rollouts if self.track is not None else 0)

    def _continues(self, waypoints: np.ndarray) -> bool:
        """True when ``waypoints`` are the tail of the track's own (passed ones dropped)."""
        old = self._waypoints
        k = len(waypoints)
        return 0 < k <= len(old) and bool(np.array_equal(old[len(old) - k:], waypoints))

    def cycle(self, t: float, state: npt.ArrayLike, waypoints: npt.ArrayLike,
              plan_stamp_ns: int,
              obstacles: OnChange[Iterable[tuple[str, np.ndarray]]] | None) -> GuidanceOutput:
        """The reference from ``t`` (s) for the robot at ``state`` (p_x, p_y, v_x, v_y).

        ``waypoints`` (K, 2) m: the plan, the robot's next waypoint first, the goal last
        (empty: no path); ``plan_stamp_ns`` the stamp it was published at.
        """
        x = np.asarray(state, dtype=float)
        points = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        rebuild = False
        if obstacles is not None and obstacles.stamp_ns != self._obstacles_stamp:
            self._obstacles_stamp = obstacles.stamp_ns
            self._polygons = [np.asarray(p, dtype=float) for _, p in obstacles.read()]
            rebuild = True
        if plan_stamp_ns != self._plan_stamp:
            self._plan_stamp = plan_stamp_ns
            rebuild = rebuild or not self._continues(points)
        if not len(points) or (len(points) == 1 and np.hypot(*(points[0] - x[:2])) < 1e-9):
            self._drop_track()     # no path, or nothing left of it but the robot's place
        elif rebuild or self.track is None:
            self._drop_track()
            self._waypoints = points.copy()
            self.track = GuidanceTrack(np.vstack((x[None, :2], points)), self._polygons,
                                       self.config)
        if self.track is None:
            return self._output(self._hold(t, x[:2]), ReferenceStatus.NO_PATH)
        reference = self.track.reference(x[:2], x[2:4], t)
        status = self.track.status
        return self._output(reference, ReferenceStatus(status.value if status is not None
                                                       else ReferenceStatus.LENGTH))

    def _drop_track(self) -> None:
        if self.track is not None:
            self._rollouts += self.track.rollouts
        self.track = None
        self._waypoints = np.zeros((0, 2))

    def _hold(self, t: float, position: np.ndarray) -> Reference:
        count = int(round(self.config.horizon / self.config.dt)) + 1
        times = t + self.config.dt * np.arange(count)
        return Reference(times, np.repeat(position[None], count, axis=0), np.zeros((count, 2)))

    def _output(self, reference: Reference, status: ReferenceStatus) -> GuidanceOutput:
        return GuidanceOutput(reference, status, self.rollouts, self._obstacles_stamp or 0,
                              self._plan_stamp)
