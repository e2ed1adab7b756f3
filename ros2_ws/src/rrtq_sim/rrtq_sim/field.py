"""A position-dependent disturbance: smooth bumps of acceleration over the plane.

The ground truth for learned disturbance bounds (``docs/margins.md``): each bump adds
``value · b(‖p − center‖ / radius)`` to the robot's acceleration at position p, with the
C^∞ bump b(s) = exp(1 − 1/(1 − s²)) for s < 1 and 0 beyond (b(0) = 1: ``value`` is the
acceleration at the centre; the support is the closed disc of ``radius``). Bumps add up.

How it composes with the time models of :mod:`rrtq_sim.disturbance`: the field is an
acceleration, so it enters the velocity rows of the state, through
E = [0; I₂] (:func:`field_input_matrix`), beside whatever F d(t) the time model applies:

    ẋ = A x̄ + B u + F d(t) + E a(p),

with p the position at the start of each step, held over the step like u and d (the
zero-order hold of :class:`rrtq_sim.plant.Plant`). A plant built with the input matrix
[F | E] (:func:`compose_input_matrix`) and the disturbance vector [d(t), a(p)] integrates
both exactly.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = ['Bump', 'DisturbanceField', 'bump_profile', 'field_input_matrix',
           'compose_input_matrix']


def bump_profile(s: npt.ArrayLike) -> np.ndarray:
    """b(s) = exp(1 − 1/(1 − s²)) for |s| < 1, else 0: smooth, b(0) = 1, support [−1, 1]."""
    r = np.abs(np.asarray(s, dtype=float))
    out = np.zeros_like(r)
    inside = r < 1.0
    out[inside] = np.exp(1.0 - 1.0 / (1.0 - r[inside] ** 2))
    return out


@dataclasses.dataclass(frozen=True)
class Bump:
    """One smooth bump of acceleration."""

    center: tuple[float, float]
    """(x, y), m."""
    radius: float
    """Radius of the support, m (> 0): the bump is zero from this distance on."""
    value: tuple[float, float]
    """(a_x, a_y), m/s²: the acceleration at the centre."""

    def __post_init__(self) -> None:
        for name, pair in (('center', self.center), ('value', self.value)):
            if len(pair) != 2 or not all(math.isfinite(v) for v in pair):
                raise ValueError(f'{name} must be two finite numbers, got {pair!r}')
        if not (math.isfinite(self.radius) and self.radius > 0.0):
            raise ValueError(f'radius must be finite and > 0, got {self.radius!r}')


class DisturbanceField:
    """The sum of :class:`Bump` accelerations, a(p) in m/s², vectorised over positions."""

    def __init__(self, bumps: Sequence[Bump]) -> None:
        self.bumps = tuple(bumps)
        self._centers = np.array([b.center for b in self.bumps], dtype=float).reshape(-1, 2)
        self._radii = np.array([b.radius for b in self.bumps], dtype=float)
        self._values = np.array([b.value for b in self.bumps], dtype=float).reshape(-1, 2)

    def acceleration(self, position: npt.ArrayLike) -> np.ndarray:
        """a(p), m/s², for one position (2,) or many (k, 2); the shape follows the input.

        Only the first two components are read, so a full state may be passed.
        """
        p = np.asarray(position, dtype=float)
        pts = p[..., :2].reshape(-1, 2)
        s = np.linalg.norm(pts[:, None, :] - self._centers[None], axis=2) / self._radii
        a = bump_profile(s) @ self._values
        return a.reshape(p.shape[:-1] + (2,))

    def peak(self) -> float:
        """An upper bound of ‖a(p)‖ over the plane, m/s² (the sum of the bumps' peaks)."""
        return float(np.linalg.norm(self._values, axis=1).sum())


def field_input_matrix(n: int) -> np.ndarray:
    """E (n x 2): the field's acceleration on state components 2, 3 (the rover's velocities)."""
    if n < 4:
        raise ValueError(f'the field acts on velocity components 2 and 3: needs n >= 4, got {n}')
    e = np.zeros((n, 2))
    e[2, 0] = e[3, 1] = 1.0
    return e


def compose_input_matrix(F: npt.ArrayLike | None, n: int) -> np.ndarray:
    """[F | E]: the time model's F (n x q, or None) followed by the field's E (n x 2)."""
    f = np.zeros((n, 0)) if F is None else np.array(F, dtype=float, ndmin=2)
    if f.shape[0] != n:
        raise ValueError(f'F must have {n} rows, got shape {f.shape}')
    return np.hstack([f, field_input_matrix(n)])
