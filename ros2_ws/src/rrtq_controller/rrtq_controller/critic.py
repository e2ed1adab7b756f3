"""Critic tuning laws over the integral Bellman errors e_c1, e_c2 (RRT-QX (20)-(22)).

Both laws see the same data: regression rows (σ, k) whose residual σθ + k is the critic
error, with θ the learned critic weights (the pairs that involve x̄, for every time
function). Each control step gives two rows, the integral Bellman row (e_c1) and the
terminal row (e_c2, sign flipped to a residual); see :mod:`bellman`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .config import ControllerConfig, CriticLaw

Array = NDArray[np.float64]
RowBuilder = Callable[..., tuple[Array, Array, Array, Array]]
"""(τ0, x̄0, τ1, x̄1, u, d) batches -> (σ, k, σ_f, k_f), see :func:`bellman.bellman_rows`."""


class GradientCritic:
    """Normalised gradient descent on K1 = ½ e_c1² + ½ e_c2², RRT-QX (22) / ACC (21).

    ``Ŵc ← Ŵc - α_c Δt Σ_rows σ e / (1 + σᵀσ)²``, the explicit-Euler step of (22).
    The papers write the terminal term with ``+σ_f e_c2``; with e_c2 defined as target
    minus estimate that is gradient *ascent*, so here both rows enter as residuals.
    Each row contracts the error along σ by α_c Δt σᵀσ / (1 + σᵀσ)² <= α_c Δt / 4, so the
    two rows together are stable for α_c Δt < 4 (the paper's α_c = 90, Δt = 0.05 gives 4.5).
    """

    def __init__(self, theta0: Array, config: ControllerConfig) -> None:
        self.theta = theta0.astype(float).copy()
        self._gain = config.gains.alpha_c * config.dt

    def update(self, sig: Array, k: Array) -> None:
        """Apply one Euler step of (22) for rows σ (R, K) with errors e = σθ + k."""
        e = sig @ self.theta + k
        s2 = np.einsum('ij,ij->i', sig, sig)
        self.theta -= self._gain * (sig.T @ (e / (1.0 + s2) ** 2))


class LeastSquaresCritic:
    """Least squares over the same rows, re-solved from a window of stored samples.

    Each row evaluates the actors' *current* policy: the off-policy form of e_c1 (see
    :mod:`bellman`) holds for data taken under any input, so every stored sample (x̄ and
    the held u, d at both ends of its Δt) yields a valid row for whatever policy the
    actors now hold. Rows of older policies are therefore never mixed in (the trouble of
    a recursive estimator under a moving actor); instead the rows are re-formed for the
    current actors at every evaluation (policy evaluation; the actor law (23) then does
    the improvement). Rows are normalised by (1 + σᵀσ)^½ as in the gradient law, and a
    small ridge pulls towards the previous estimate,
    ``θ = argmin Σ (σθ + k)² / (1 + σᵀσ) + ε ‖θ - θ_prev‖²``, so that directions the
    data do not excite (time functions that vanish on the visited τ) stay where they were.
    """

    def __init__(self, theta0: Array, config: ControllerConfig, n: int, m: int, q: int) -> None:
        self.theta = theta0.astype(float).copy()
        C = config.critic_memory
        self._tau0, self._tau1 = np.zeros(C), np.zeros(C)
        self._x0, self._x1 = np.zeros((C, n)), np.zeros((C, n))
        self._u, self._d = np.zeros((C, m)), np.zeros((C, q))
        self.count = 0
        self._head = 0
        self._ridge = config.ridge

    def add_sample(self, tau0: float, x0: Array, tau1: float, x1: Array, u: Array, d: Array) -> None:
        """Store one Δt: time-to-go and state at both ends, the held control and disturbance."""
        i = self._head
        self._tau0[i], self._tau1[i], self._x0[i], self._x1[i] = tau0, tau1, x0, x1
        self._u[i], self._d[i] = u, d
        self._head = (i + 1) % len(self._tau0)
        self.count = min(self.count + 1, len(self._tau0))

    def evaluate(self, rows: RowBuilder) -> None:
        """Policy evaluation: solve for θ over all stored samples with the current actors."""
        if self.count == 0:
            return
        c = self.count
        sig, k, sig_f, k_f = rows(self._tau0[:c], self._x0[:c], self._tau1[:c], self._x1[:c],
                                  self._u[:c], self._d[:c])
        S = np.vstack([sig, sig_f])
        y = -np.concatenate([k, k_f])
        w = 1.0 / (1.0 + np.einsum('ij,ij->i', S, S))
        G = S.T @ (w[:, None] * S)
        eps = self._ridge * (np.trace(G) / self.theta.size + 1e-12)
        # θ's size is read here: widening the time basis enlarges it
        self.theta = np.linalg.solve(G + eps * np.eye(self.theta.size), S.T @ (w * y) + eps * self.theta)


Critic = GradientCritic | LeastSquaresCritic


def make_critic(theta0: Array, config: ControllerConfig, n: int, m: int, q: int) -> Critic:
    """The critic for ``config.critic_law``."""
    if config.critic_law is CriticLaw.GRADIENT:
        return GradientCritic(theta0, config)
    return LeastSquaresCritic(theta0, config, n, m, q)
