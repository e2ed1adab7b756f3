"""Gain checks against the stability bounds: RRT-QX (25) and ACC 2019 Theorem 2.

The bounds are stated with the ideal Q_xu = PB (and Q_xd = PF), which a model-free
controller does not know; they are evaluated with the critic's current estimates on a
grid of the time-to-go over [T/2, T] (where legs spend their time and the critic is
identified; it only extrapolates towards τ = 0) and taken at their smallest. Two
readings were necessary:

* ``λ̄(μ(t) R⁻¹ / ‖1 + μ(t)ᵀμ(t)‖²)`` multiplies an n x n by an m x m matrix; with
  μ(τ) = φ(τ) ⊗ I_n it is read as ``‖φ(τ)‖ λ̄(R⁻¹) / (1 + ‖φ(τ)‖²)²``.
* ACC's α_d bound has ``λ(Q_xd Q_xdᵀ)``, an n x n matrix of rank q: for q < n (the rover,
  q = 1) its smallest eigenvalue is 0 and the literal bound admits no α_d > 0. It is
  evaluated with the q x q Gram matrix Q_xdᵀ Q_xd (the nonzero eigenvalues) instead.

Besides the Lyapunov bounds, the discrete (Euler) steps have their own limits: the
normalised gradient-critic step (two rows) needs α_c Δt < 4, the actor steps α Δt < 2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from .basis import TimeBasis
from .config import ControllerConfig, CriticLaw, Gains


class Critic(Protocol):
    """What the bounds read of a controller (:class:`rrtq_controller.q_learning.QLearningController`)."""

    config: ControllerConfig
    gains: Gains
    gamma: float
    robust: bool
    time_basis: TimeBasis

    def _cross(self, phi: NDArray[np.float64], which: str) -> NDArray[np.float64]: ...


@dataclass(frozen=True)
class GainBounds:
    """Upper bounds on the gains (1/s); ``inf`` where a bound does not apply."""

    alpha_a: float
    """RRT-QX (25) (nominal) or ACC Theorem 2 (robust), min over τ."""
    alpha_d: float
    """ACC Theorem 2 (robust), min over τ, with the Gram-matrix reading."""


def gain_bounds(ctrl: Critic, samples: int = 21) -> GainBounds:
    """Evaluate RRT-QX (25) / ACC Theorem 2 with the critic's Q̂_xu(τ), Q̂_xd(τ)."""
    c = ctrl.config
    delta = c.stability_delta
    r_inv = float(np.linalg.eigvalsh(np.linalg.inv(c.R)).max())
    bound_a = bound_d = np.inf
    for tau in np.linspace(0.5 * c.horizon, c.horizon, samples):
        phi = ctrl.time_basis(tau)
        nphi = float(np.linalg.norm(phi))
        norm = nphi / (1.0 + nphi**2) ** 2
        Qxu = ctrl._cross(phi, 'u').T
        S = c.M + Qxu @ np.linalg.inv(c.R) @ Qxu.T
        cross = float(np.linalg.eigvalsh(Qxu @ Qxu.T).max())
        if ctrl.robust:
            Qxd = ctrl._cross(phi, 'd').T
            S = S - ctrl.gamma**-2 * Qxd @ Qxd.T
            num = float(np.linalg.eigvalsh(S).min()) - cross
            if np.any(Qxd):  # undetermined until the critic has learned something
                gram = float(np.linalg.eigvalsh(Qxd.T @ Qxd).min())
                bound_d = min(bound_d, gram / (delta * norm * ctrl.gamma**-2))
        else:
            num = 2.0 * float(np.linalg.eigvalsh(S).min()) - cross
        bound_a = min(bound_a, num / (delta * norm * r_inv))
    return GainBounds(alpha_a=bound_a, alpha_d=bound_d)


def gain_warnings(ctrl: Critic) -> list[str]:
    """Human-readable warnings for every configured gain that violates a bound."""
    c, g = ctrl.config, ctrl.gains
    out: list[str] = []
    bounds = gain_bounds(ctrl)
    law = 'ACC Theorem 2' if ctrl.robust else 'RRT-QX (25)'
    if not 0 < g.alpha_a < bounds.alpha_a:
        out.append(f'alpha_a = {g.alpha_a:g} violates {law}: need 0 < alpha_a < {bounds.alpha_a:.4g}')
    if ctrl.robust and not 0 < g.alpha_d < bounds.alpha_d:
        out.append(f'alpha_d = {g.alpha_d:g} violates ACC Theorem 2: need 0 < alpha_d < {bounds.alpha_d:.4g}'
                   ' (with the current critic estimate of Q_xd)')
    if c.critic_law is CriticLaw.GRADIENT:
        if g.alpha_c < 10.0 * max(g.alpha_a, g.alpha_d if ctrl.robust else 0.0):
            out.append(f'alpha_c = {g.alpha_c:g} is not >> the actor gains (want >= 10x)')
        if g.alpha_c * c.dt >= 4.0:
            out.append(f'alpha_c * dt = {g.alpha_c * c.dt:g} >= 4: the normalised critic step can overshoot')
    if g.alpha_a * c.dt >= 2.0 or (ctrl.robust and g.alpha_d * c.dt >= 2.0):
        out.append('alpha_a * dt or alpha_d * dt >= 2: the normalised actor step is unstable')
    return out
