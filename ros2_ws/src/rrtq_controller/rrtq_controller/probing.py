"""Probing noise of the actors: slow (Ornstein-Uhlenbeck) and shaped along the leg."""

from __future__ import annotations

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
    """

    def __init__(self, size: int, dt: float, correlation: float, across: float,
                 rng: np.random.Generator) -> None:
        self._a = float(np.exp(-dt / correlation)) if correlation > 0 else 0.0
        self._across = across
        self._rng = rng
        self._state = np.zeros(size)
        self._axes = np.eye(size)

    def start_leg(self, x0: Array) -> None:
        """Axes of the leg from x̄0: the full standard deviation along it, a fraction across.

        Probing across the leg pushes the robot off its straight edge, which the safety
        node then adds to every obstacle; along the leg it does not. The forces are the
        map-frame force components (u = (f_x, f_y)), so the leg's direction in the plane
        is a direction of the inputs too.
        """
        length = float(np.linalg.norm(x0[:2]))
        if self._state.size != 2 or length < 1e-9:
            self._axes = np.eye(self._state.size)
            return
        e = x0[:2] / length
        self._axes = np.array([[e[0], -e[1]], [e[1], e[0]]]) @ np.diag([1.0, self._across])

    def sample(self, std: float) -> Array:
        """Next sample, stationary standard deviation ``std`` (along the leg)."""
        a = self._a
        self._state = (a * self._state * (std > 0)
                       + np.sqrt(1.0 - a * a) * std * self._rng.standard_normal(self._state.size))
        return self._axes @ self._state
