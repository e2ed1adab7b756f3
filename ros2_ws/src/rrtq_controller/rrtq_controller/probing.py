"""Probing noise of the actors: slow (Ornstein-Uhlenbeck) and shaped along the leg."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


class Probing:
    """Ornstein-Uhlenbeck probing of ``size`` inputs, with axes set per leg.

    Slow probing moves the robot (excites velocities) where white noise at 1/Δt averages
    out in the plant; the off-policy critic needs no whiteness.

    Parameters
    ----------
    size
        Number of inputs.
    dt, correlation
        Step and correlation time of the process, s (correlation 0: white noise).
    across
        Fraction of the standard deviation applied across the leg (see :meth:`start_leg`).
    rng
        The controller's generator.
    line_fraction
        Beyond this fraction of the leg's length from its line, the probing across the leg
        is turned toward the line (see :meth:`sample`); inf: never.
    """

    def __init__(self, size: int, dt: float, correlation: float, across: float,
                 rng: np.random.Generator, line_fraction: float = math.inf) -> None:
        self._a = float(np.exp(-dt / correlation)) if correlation > 0 else 0.0
        self._across = across
        self._rng = rng
        self._state = np.zeros(size)
        self._axes = np.eye(size)
        self._line_fraction = line_fraction
        self._normal: Array | None = None
        self._length = 0.0

    def start_leg(self, x0: Array) -> None:
        """Axes of the leg from x̄0: the full standard deviation along it, a fraction across.

        Probing across the leg pushes the robot off its straight edge, which the safety
        node then adds to every obstacle; along the leg it does not. The forces are the
        map-frame force components (u = (f_x, f_y)), so the leg's direction in the plane
        is a direction of the inputs too.
        """
        self.follow_line(x0)
        if self._normal is None:
            self._axes = np.eye(self._state.size)
            return
        e = x0[:2] / self._length
        self._axes = np.array([[e[0], -e[1]], [e[1], e[0]]]) @ np.diag([1.0, self._across])

    def follow_line(self, x0: Array) -> None:
        """The line the probing yields to: through the target and x̄0's position (m)."""
        self._length = float(np.linalg.norm(x0[:2])) if x0.size >= 2 else 0.0
        self._normal = None
        if self._state.size == 2 and self._length > 1e-9:
            self._normal = np.array([-x0[1], x0[0]]) / self._length

    def sample(self, std: float, position: Array | None = None) -> Array:
        """Next sample, stationary standard deviation ``std`` (along the leg).

        With the robot's ``position`` seen from the leg's target (x̄[:2]) farther than
        ``line_fraction`` of the leg's length from its line, a sample whose component
        across the leg points away from the line is reflected across the line's
        direction: its size, and the component along the leg, are kept (beyond the
        papers). A weak early policy leaves the robot to the probing, which otherwise
        walks it off its line: on the random plants of the robustness bench, light rovers
        went 0.52-0.68 of a 2.4-3.4 m leg's length off it, with the probing 3-4 times the
        policy's force. The probing is the same process; only its output is turned, and
        the Bellman rows take the force applied in any case.
        """
        a = self._a
        self._state = (a * self._state * (std > 0)
                       + np.sqrt(1.0 - a * a) * std * self._rng.standard_normal(self._state.size))
        out = self._axes @ self._state
        if position is None or self._normal is None:
            return out
        off = float(self._normal @ np.asarray(position, dtype=float)[:2])
        across = float(self._normal @ out)
        if abs(off) > self._line_fraction * self._length and across * off > 0.0:
            out = out - 2.0 * across * self._normal
        return out
