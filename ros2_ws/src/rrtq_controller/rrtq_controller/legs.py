"""Leg sequencing and terminal-state evaluation (RRT-QX (4)-(5), Algorithm 1 lines 6, 17-22).

A plan is a list of 2-D waypoints; each leg is the finite-horizon problem from the
state where the previous one ended to the next waypoint, held at rest:
x_r = (p_x, p_y, 0, 0). D0 = ‖x̄0‖ at the leg start (4) and D = ‖x̄‖ every step (5); when
D <= ρ D0 the current state becomes the next leg's initial state.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


class LegEvent(enum.Enum):
    """What :meth:`LegSequencer.update` decided this step."""

    CONTINUE = 'continue'
    NEW_LEG = 'new_leg'
    """A new leg starts now (next waypoint, new plan, or horizon restart)."""
    GOAL_REACHED = 'goal_reached'
    """The window of the last waypoint was entered; the leg continues (station keeping)."""
    NO_PLAN = 'no_plan'
    RENEWED = 'renewed'
    """Station keeping on the last waypoint ran through its horizon: a new leg to the same
    target starts with a fresh horizon (receding; the goal stays reached), since past it
    the finite-horizon gain K(0) holds no position (R⁻¹BᵀP(T): velocity only) and the
    learned one is unidentified there."""


@dataclass(frozen=True)
class Leg:
    """One boundary value problem: from x0 (full state) to the waypoint at rest."""

    index: int
    """Increments with every new leg, 0 for the first."""
    start_time: float
    """s."""
    x0: Array
    target: Array
    """Target state x_r (position of the waypoint, zero velocity)."""
    d0: float
    """D0 = ‖x0 - x_r‖ (RRT-QX (4))."""


class LegSequencer:
    """Walk a plan's waypoints with the terminal-state evaluation D <= ρ D0.

    Parameters
    ----------
    rho
        Admissible window ρ (RRT-QX §2).
    horizon
        T, s. A leg that has not entered its window after T restarts towards the same
        waypoint from the current state (the finite-horizon problem is posed anew).
    n
        State dimension; the first two entries are the position.
    skip_radius
        Leading waypoints closer than this to the robot (m) are skipped (the plan usually
        starts where the robot is).
    """

    def __init__(self, rho: float, horizon: float, n: int = 4, skip_radius: float = 1e-3) -> None:
        self.rho, self.horizon, self.n, self.skip_radius = rho, horizon, n, skip_radius
        self._waypoints: list[Array] = []
        self._next = 0
        self.leg: Leg | None = None
        self._count = -1
        self.goal_reached = False
        self.completed = False
        """Whether the last :meth:`update` found the leg in its window (a new leg to the
        next waypoint, or the goal reached; not a horizon restart, not a new plan), from a
        start away from its target: a leg of no length (a hold where the robot already
        is) proves nothing about the policy."""

    def set_plan(self, waypoints: ArrayLike, x: ArrayLike, t: float) -> Leg | None:
        """Adopt a new plan; a new leg starts from the current state x at time t (s)."""
        pts = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        x = np.asarray(x, dtype=float)
        self._waypoints = [p for p in pts]
        self._next = 0
        while (self._next < len(self._waypoints) - 1
               and np.linalg.norm(self._waypoints[self._next] - x[:2]) <= self.skip_radius):
            self._next += 1
        self.goal_reached = False
        if not self._waypoints:
            self.leg = None
            return None
        return self._start(x, t)

    def follow_plan(self, waypoints: ArrayLike, x: Array, t: float) -> bool:
        """Adopt a new plan without breaking the current leg when it can go on.

        When the plan passes through the current leg's target (within ``skip_radius``),
        the leg continues and the waypoints after the target follow it; the controller's
        own progress (the window D <= ρ D0) is kept even where the planner's notion of
        the robot's next waypoint lags behind: the waypoints before the target must all be
        behind the robot (:meth:`_behind`). A plan with a waypoint ahead of the robot
        before the target is a new route to it (the straight way to the target is not what
        the planner checked): it is adopted afresh (:meth:`set_plan`), as is a plan that no
        longer passes through the target. Returns True when a new leg started.
        """
        pts = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        if self.leg is not None and len(pts):
            near = np.flatnonzero(
                np.linalg.norm(pts - self.leg.target[:2], axis=1) <= self.skip_radius)
            hits = [int(j) for j in near if self._behind(pts[:j + 1], x[:2])]
            if hits:
                j = hits[-1]
                self._waypoints = [p for p in pts]
                self._next = j
                if j < len(pts) - 1:
                    self.goal_reached = False
                return False
        return self.set_plan(pts, x, t) is not None

    def _behind(self, pts: Array, p: Array) -> bool:
        """Whether the robot at p is past every waypoint of pts but the last.

        Past a waypoint: within ``skip_radius`` of it, or beyond it along the plan's edge
        to the next one.
        """
        for a, b in zip(pts[:-1], pts[1:]):
            if np.linalg.norm(p - a) > self.skip_radius and float((p - a) @ (b - a)) <= 0.0:
                return False
        return True

    def target_state(self, waypoint: Array) -> Array:
        """x_r: the waypoint position at rest."""
        xr = np.zeros(self.n)
        xr[:2] = waypoint
        return xr

    def x_bar(self, x: ArrayLike) -> Array:
        """x̄ = x - x_r of the current leg."""
        assert self.leg is not None
        return np.asarray(x, dtype=float) - self.leg.target

    def distance(self, x: ArrayLike) -> float:
        """D(x̄) = ‖x̄‖ (RRT-QX (5))."""
        return float(np.linalg.norm(self.x_bar(x)))

    def update(self, x: ArrayLike, t: float) -> LegEvent:
        """Terminal-state evaluation at time t (s) with the current full state x."""
        if self.leg is None:
            return LegEvent.NO_PLAN
        x = np.asarray(x, dtype=float)
        inside = self.distance(x) <= self.rho * self.leg.d0
        last = self._next >= len(self._waypoints) - 1
        self.completed = False
        if self.goal_reached and last and t - self.leg.start_time >= self.horizon:
            self._start(x, t)              # the same target: a new leg index, as in the report
            return LegEvent.RENEWED
        if inside and not last:
            self.completed = self.leg.d0 > self.skip_radius
            self._next += 1
            self._start(x, t)
            return LegEvent.NEW_LEG
        if inside and last:
            if not self.goal_reached:
                self.completed = self.leg.d0 > self.skip_radius
                self.goal_reached = True
                return LegEvent.GOAL_REACHED
            return LegEvent.CONTINUE
        if t - self.leg.start_time >= self.horizon and not self.goal_reached:
            self._start(x, t)
            return LegEvent.NEW_LEG
        return LegEvent.CONTINUE

    def _start(self, x: Array, t: float) -> Leg:
        self._count += 1
        target = self.target_state(self._waypoints[self._next])
        self.leg = Leg(self._count, float(t), x.copy(), target, float(np.linalg.norm(x - target)))
        return self.leg
