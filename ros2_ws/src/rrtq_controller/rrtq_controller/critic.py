"""Critic tuning laws over the integral Bellman errors e_c1, e_c2 (RRT-QX (20)-(22)).

Both laws see the same data: regression rows (σ, k) whose residual σθ + k is the critic
error, with θ the learned critic weights (the pairs that involve x̄, for every time
function). Each control step gives two rows, the integral Bellman row (e_c1) and the
terminal row (e_c2, sign flipped to a residual); see :mod:`bellman`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .config import ControllerConfig, CriticLaw

Array = NDArray[np.float64]
RowBuilder = Callable[..., tuple[Array, Array, Array, Array]]
"""(τ0, x̄0, τ1, x̄1, u, d) batches -> (σ, k, σ_f, k_f), see :func:`bellman.bellman_rows`."""


class SampleWindow:
    """The last ``critic_memory`` Δt samples: time-to-go and state at both ends, held u and d.

    Each sample yields a Bellman row for *any* policy (the off-policy form of e_c1, see
    :mod:`bellman`), so the window serves the least-squares policy evaluation and the
    guard's checks of a proposed policy alike. It keeps each sample as measured (the
    odometry, the force applied) and, for learning, the same sample as the robot's
    :class:`rrtq_controller.observer.Observer` estimates it (smoothed states, the
    equivalent input): :meth:`samples` gives the latter, which are the measured ones until
    :meth:`estimate` replaces them.
    """

    def __init__(self, capacity: int, n: int, m: int, q: int) -> None:
        C = capacity
        self._tau0, self._tau1 = np.zeros(C), np.zeros(C)
        self._x0, self._x1 = np.zeros((C, n)), np.zeros((C, n))
        self._u, self._d = np.zeros((C, m)), np.zeros((C, q))
        self._measured = (np.zeros((C, n)), np.zeros((C, n)), np.zeros((C, m)))
        self._step = np.full(C, -1, dtype=np.int64)
        self.count = 0
        self._head = 0

    def add_sample(self, tau0: float, x0: Array, tau1: float, x1: Array, u: Array, d: Array,
                   step: int = -1) -> None:
        """Store one Δt: time-to-go and state at both ends, the applied control and disturbance.

        ``step``: the id of its first end in the observer's log (-1: none).
        """
        i = self._head
        self._tau0[i], self._tau1[i], self._x0[i], self._x1[i] = tau0, tau1, x0, x1
        self._u[i], self._d[i], self._step[i] = u, d, step
        for stored, value in zip(self._measured, (x0, x1, u), strict=True):
            stored[i] = value
        self._head = (i + 1) % len(self._tau0)
        self.count = min(self.count + 1, len(self._tau0))

    def samples(self) -> tuple[Array, Array, Array, Array, Array, Array]:
        """(τ0, x̄0, τ1, x̄1, u, d) of every stored sample as learned from (views; not in time order)."""
        c = self.count
        return (self._tau0[:c], self._x0[:c], self._tau1[:c], self._x1[:c], self._u[:c], self._d[:c])

    def applied(self) -> Array:
        """The force applied in each stored sample, as commanded (N; the order of :meth:`samples`)."""
        return self._measured[2][:self.count]

    def order(self) -> NDArray[np.intp]:
        """Indices of the stored samples in the order they were taken (oldest first)."""
        c, capacity = self.count, len(self._tau0)
        return np.arange(c) if c < capacity else (np.arange(c) + self._head) % capacity

    def steps(self) -> NDArray[np.int64]:
        """The observer's step id of each stored sample's first end (the order of :meth:`samples`)."""
        return self._step[:self.count]

    def estimate(self, x0: Array, x1: Array, u: Array, known: NDArray[np.bool_],
                 d: Array | None = None) -> None:
        """Learn from these states and inputs where ``known``, from the measured ones elsewhere.

        Arrays in the order of :meth:`samples`; ``d``: the disturbance too (a game against
        an estimated one), where ``known`` (elsewhere it stays as stored).
        """
        c = self.count
        for learned, measured, value in zip((self._x0, self._x1, self._u), self._measured,
                                            (x0, x1, u), strict=True):
            learned[:c] = np.where(known[:, None], value, measured[:c])
        if d is not None:
            self._d[:c] = np.where(known[:, None], d, self._d[:c])


def _system(rows: RowBuilder, window: SampleWindow) -> tuple[Array, Array, Array]:
    """Stacked rows S, targets y and row weights w = 1 / (1 + σᵀσ) of the window's samples."""
    sig, k, sig_f, k_f = rows(*window.samples())
    S = np.vstack([sig, sig_f])
    y = -np.concatenate([k, k_f])
    return S, y, 1.0 / (1.0 + np.einsum('ij,ij->i', S, S))


def _relative_residual(S: Array, y: Array, w: Array, theta: Array) -> float:
    e = S @ theta - y
    scale = float(np.sqrt(w @ (y * y)))
    return float(np.sqrt(w @ (e * e))) / scale if scale > 0 else 0.0


@dataclass(frozen=True)
class Fit:
    """A least-squares critic fit and how far its weights can be from the truth by noise."""

    theta: Array
    residual: float
    """The relative residual √(Σ w e²) / √(Σ w y²) (0 when no data)."""
    noise: float = 0.0
    """The part of :attr:`residual` that noise explains: √(N σ̂²) / √(Σ w y²), σ̂² the
    variance of the weighted residuals √w e of the Bellman rows estimated from their
    differences :data:`LONG_RUN_LAGS` steps apart in time order (Rice's difference estimator:
    a critic that cannot represent the Q-function leaves a residual that varies slowly
    along the trajectory, which differences cancel; noise does not vary slowly)."""
    spread: Array | None = None
    """Σ_θ (p x p): the covariance of θ, a sandwich estimate (heteroscedastic rows) inflated
    by the long-run variance of the residuals in time order; None without data."""

    @property
    def misfit(self) -> float:
        """The relative residual less its noise part, √(max(residual² - noise², 0))."""
        return math.sqrt(max(self.residual ** 2 - self.noise ** 2, 0.0))

    def standard_errors(self, g: Array) -> Array:
        """The standard error of gᵀθ for each row g of ``g`` (k, p): √(gᵀ Σ_θ g)."""
        if self.spread is None:
            return np.zeros(len(g))
        return np.sqrt(np.maximum(np.einsum('ij,jk,ik->i', g, self.spread, g), 0.0))


LONG_RUN_LAGS = 20
"""Lags (Δt each: 1 s) of the residuals' autocorrelation in the long-run variance of a fit:
neighbouring rows share a state, and smoothed states share their neighbours' noise."""


def fit(rows: RowBuilder, window: SampleWindow, prior: Array, ridge: float) -> Fit:
    """Least squares over the window's rows for the policy that ``rows`` forms them for.

    ``θ = argmin Σ (σθ + k)² / (1 + σᵀσ) + ε ‖θ - θ_prior‖²`` (rows normalised as in the
    gradient law; the ridge ε, relative to the mean non-zero diagonal of the normal
    matrix, keeps directions the data do not excite where they were).

    The covariance of θ (:attr:`Fit.spread`) is the sandwich A⁻¹ (Σ w² e² σσᵀ) A⁻¹ with A the
    regularised normal matrix (White's estimator: rows of unequal noise), times the
    Bartlett-weighted sum of the residuals' autocorrelations over :data:`LONG_RUN_LAGS`
    steps of the window in time order (Newey-West's long-run variance, for a scalar
    factor): what the guard's tests of a fit use to tell noise from a wrong critic.
    """
    if window.count == 0:
        return Fit(prior.copy(), 0.0)
    S, y, w = _system(rows, window)
    G = S.T @ (w[:, None] * S)
    # the mean over the directions the rows reach: the disturbance's weights of a run
    # without one (d = 0 throughout) neither move nor change the others' fit
    eps = ridge * (np.trace(G) / max(np.count_nonzero(np.diag(G)), 1) + 1e-12)
    A = G + eps * np.eye(prior.size)
    theta = np.linalg.solve(A, S.T @ (w * y) + eps * prior)
    e = S @ theta - y
    h = S * (w * e)[:, None]
    Ainv = np.linalg.inv(A)
    order = window.order()
    spread = Ainv @ (h.T @ h) @ Ainv * _long_run_factor(e[:window.count], order)
    r = (np.sqrt(w) * e)[:window.count][order]
    L = LONG_RUN_LAGS
    scale = float(np.sqrt(w @ (y * y)))
    noise = (math.sqrt(len(r) * float(np.mean((r[L:] - r[:-L]) ** 2)) / 2.0) / scale
             if len(r) > 2 * L and scale > 0 else 0.0)
    return Fit(theta, _relative_residual(S, y, w, theta), noise, 0.5 * (spread + spread.T))


def _long_run_factor(e: Array, order: NDArray[np.intp]) -> float:
    """1 + 2 Σ_k (1 - k / (L + 1)) ρ_k of residuals e in time order (at least 1)."""
    r = e[order] - e.mean()
    var = float(r @ r)
    if var <= 0.0 or len(r) < 2 * LONG_RUN_LAGS:
        return 1.0
    rho = [float(r[:-k] @ r[k:]) / var for k in range(1, LONG_RUN_LAGS + 1)]
    factor = 1.0 + 2.0 * sum((1.0 - k / (LONG_RUN_LAGS + 1)) * rk for k, rk in enumerate(rho, 1))
    return max(factor, 1.0)


def residual(rows: RowBuilder, window: SampleWindow, theta: Array) -> float:
    """The relative residual of :func:`fit` for a given θ (0 when no data)."""
    if window.count == 0:
        return 0.0
    return _relative_residual(*_system(rows, window), theta)


class GradientCritic:
    """Normalised gradient descent on K1 = ½ e_c1² + ½ e_c2², RRT-QX (22) / ACC (21).

    ``Ŵc ← Ŵc - α_c Δt Σ_rows σ e / (1 + σᵀσ)²``, the explicit-Euler step of (22).
    The papers write the terminal term with ``+σ_f e_c2``; with e_c2 defined as target
    minus estimate that is gradient *ascent*, so here both rows enter as residuals.
    Each row contracts the error along σ by α_c Δt σᵀσ / (1 + σᵀσ)² <= α_c Δt / 4, so the
    two rows together are stable for α_c Δt < 4 (the paper's α_c = 90, Δt = 0.05 gives 4.5).
    The sample window is kept for the guard's checks only.
    """

    def __init__(self, theta0: Array, config: ControllerConfig, n: int, m: int, q: int) -> None:
        self.theta = theta0.astype(float).copy()
        self._gain = config.gains.alpha_c * config.dt
        self.window = SampleWindow(config.critic_memory, n, m, q)
        self.residual = 0.0
        self.last = Fit(self.theta, 0.0)
        """The guard's view of the weights: no spread (the gradient law has no fit)."""

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
    current actors at every evaluation (policy evaluation, :func:`fit`; the actor law (23)
    then does the improvement), with a small ridge toward the previous estimate so that
    directions the data do not excite (time functions that vanish on the visited τ) stay
    where they were.
    """

    def __init__(self, theta0: Array, config: ControllerConfig, n: int, m: int, q: int) -> None:
        self.theta = theta0.astype(float).copy()
        self.window = SampleWindow(config.critic_memory, n, m, q)
        self._ridge = config.ridge
        self.residual = 0.0
        """Relative residual of the last fit (see :func:`fit`)."""
        self.last = Fit(self.theta, 0.0)
        """The last fit, with its spread."""

    def add_sample(self, tau0: float, x0: Array, tau1: float, x1: Array, u: Array, d: Array,
                   step: int = -1) -> None:
        """Store one Δt (see :meth:`SampleWindow.add_sample`)."""
        self.window.add_sample(tau0, x0, tau1, x1, u, d, step)

    @property
    def count(self) -> int:
        """Stored samples."""
        return self.window.count

    def evaluate(self, rows: RowBuilder) -> None:
        """Policy evaluation: solve for θ over all stored samples with the current actors."""
        # θ's size is read in fit: widening the time basis enlarges it
        self.last = fit(rows, self.window, self.theta, self._ridge)
        self.theta, self.residual = self.last.theta, self.last.residual


Critic = GradientCritic | LeastSquaresCritic


def make_critic(theta0: Array, config: ControllerConfig, n: int, m: int, q: int) -> Critic:
    """The critic for ``config.critic_law``."""
    if config.critic_law is CriticLaw.GRADIENT:
        return GradientCritic(theta0, config, n, m, q)
    return LeastSquaresCritic(theta0, config, n, m, q)
