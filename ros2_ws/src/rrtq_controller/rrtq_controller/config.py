"""Configuration of the Q-learning controller core (frozen, validated, with units)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray


class Variant(enum.Enum):
    """Which game the controller plays."""

    NOMINAL = 'nominal'
    """Optimal control (RRT-QX §4): critic on U = (x̄, u)."""

    ROBUST = 'robust'
    """Two-player zero-sum game (ACC 2019 §III-IV): critic on U = (x̄, u, d)."""


class CriticLaw(enum.Enum):
    """How the critic weights are tuned from the integral Bellman equations."""

    GRADIENT = 'gradient'
    """The papers' normalised gradient descent, RRT-QX (22) / ACC (21), Euler-stepped."""

    LEAST_SQUARES = 'least_squares'
    """Recursive, exponentially weighted least squares over the same errors e_c1, e_c2."""


class ActorLaw(enum.Enum):
    """How the actors follow the critic's greedy policy."""

    GRADIENT = 'gradient'
    """The papers' law RRT-QX (23) / ACC (22)-(23), a gradient of ½‖e_a‖² at the current x̄,
    Euler-stepped with normalisation: directions x̄ rarely visits (velocities) learn slowly."""

    WHITENED = 'whitened'
    """The same error averaged over isotropic x̄: Ŵ ← Ŵ - α Δt (Ŵ - Ŵ*), with Ŵ* the critic's
    greedy weights (-(R⁻¹Q̂_ux)ᵀ, γ⁻²Q̂_dxᵀ per time function); every direction alike."""


def _matrix(value: ArrayLike, size: int, name: str) -> NDArray[np.float64]:
    """Turn a scalar (times identity) or a full matrix into a read-only square array."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = float(arr) * np.eye(size)
    if arr.shape != (size, size):
        raise ValueError(f'{name} must be a scalar or a {size}x{size} matrix, got shape {arr.shape}')
    if not np.allclose(arr, arr.T):
        raise ValueError(f'{name} must be symmetric')
    arr = 0.5 * (arr + arr.T)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class ControllerConfig:
    """Parameters of the finite-horizon Q-learning controller.

    Matrices may be given as scalars (meaning scalar times identity); they are
    expanded by :meth:`expanded` once the dimensions n, m are known.
    """

    horizon: float = 10.0
    """T, s: finite horizon of every leg (RRT-QX (2))."""
    dt: float = 0.05
    """Δt, s: control period and integral-reinforcement interval (RRT-QX (17))."""
    M: Any = 10.0
    """State weight, n x n (or scalar), cost units per (state unit)²."""
    R: Any = 2.0
    """Control weight, m x m (or scalar), cost units per N². Also the fixed Q̂_uu."""
    P_T: Any = 0.5
    """Terminal Riccati matrix P(T), n x n (or scalar)."""
    variant: Variant = Variant.NOMINAL
    critic_law: CriticLaw = CriticLaw.LEAST_SQUARES
    actor_law: ActorLaw = ActorLaw.WHITENED
    alpha_c: float = 90.0
    """Critic gain α_c, 1/s (gradient law only)."""
    alpha_a: float = 1.2
    """Control-actor gain α_a, 1/s (RRT-QX (23))."""
    actor_warmup_legs: int = 1
    """Legs during which the actors stay at their initial weights while the critic learns."""
    alpha_d: float = 0.2
    """Disturbance-actor gain α_d, 1/s (ACC (23)); robust variant only.

    ACC's 2.5 (and 1.2) let the simultaneous game iteration diverge in our trials.
    """
    gamma: float = 3.0
    """Attenuation level γ (robust variant), cost units per disturbance unit."""
    rho: float = 0.15
    """Admissible window ρ of the terminal-state evaluation D <= ρ D0 (RRT-QX (4)-(5))."""
    time_rates: tuple[float, ...] = (0.0, 0.5, 1.0, 2.0)
    """Decay rates λ_l, 1/s, of the time basis φ_l(τ) = exp(-λ_l τ) of the time-to-go τ.

    The first rate must be 0 (the constant function, which carries the fixed Q̂_uu = R).
    """
    time_powers: tuple[int, ...] = ()
    """Powers k of polynomial time functions (τ / T)^k appended to the exponentials."""
    widen_powers: tuple[int, ...] = (1, 2)
    """Powers k of (τ / T)^k the time basis is widened by, once, when ``widen_after_legs``
    legs in a row ran their whole horizon (see :meth:`QLearningController.widen_time_basis`).

    The value of a policy that leaves the robot away from its target grows in τ (the zero
    policy on the rover without a spring: linearly), which no sum of decaying exponentials
    fits, so such a policy is never evaluated and nothing is learned from a zero gain. The
    powers are not used from the start: on the τ that legs visit they are nearly collinear
    with the exponentials and cost accuracy when the plant needs none (the paper's rover,
    small probing: gain error 0.47 instead of 0.08). Empty never widens.
    """
    widen_after_legs: int = 2
    """Legs in a row that end by running out of horizon after which the basis is widened."""
    probing_std: float = 20.0
    """Standard deviation of the control probing noise on the first leg, N."""
    probing_decay: float = 0.85
    """Factor applied to the probing standard deviation after every leg (the schedule)."""
    probing_floor: float = 0.0
    """Lower bound of the probing standard deviation, N."""
    probing_correlation: float = 1.0
    """Correlation time of the probing noise (Ornstein-Uhlenbeck), s; 0 gives white noise.

    Slow probing moves the robot (excites velocities) where white noise at 1/Δt averages
    out in the plant; the off-policy critic needs no whiteness.
    """
    disturbance_probing_std: float = 0.1
    """Standard deviation of the disturbance-actor probing noise on the first leg (robust)."""
    initial_gain: tuple[tuple[float, ...], ...] | None = None
    """K̂0 (m x n rows), the actor's initial gain, û = -K̂0 x̄ (N per state unit); None = 0.

    Policy evaluation needs a policy whose value the time basis can represent: on a plant
    that is not stable by itself (the rover without a spring) give a PD gain brisk enough
    to reach the window D <= ρ D0 within T (e.g. 40 N/m, 30 N s/m for the 40 kg rover); a
    sluggish one (10 N/m, 20 N s/m) runs whole horizons, its value varies on time scales
    the basis lacks, and the critic's fit of it is not trusted (see policy_evaluation).
    """
    critic_memory: int = 2000
    """Least squares: number of stored Δt samples the critic is fitted to (a window)."""
    evaluation_period: float = 2.0
    """Least squares: time between policy evaluations within a leg, s (also at leg starts)."""
    ridge: float = 1e-6
    """Least squares: ridge weight, relative to the mean diagonal of the normal matrix."""
    stability_delta: float = 1.0
    """δ, δ1, δ2 of the stability bounds (RRT-QX (25), ACC Theorem 2): constants of unity order."""

    def __post_init__(self) -> None:
        if self.horizon <= 0 or self.dt <= 0 or self.dt >= self.horizon:
            raise ValueError('need 0 < dt < horizon')
        if not self.time_rates or self.time_rates[0] != 0.0:
            raise ValueError('time_rates must start with 0.0 (the constant function)')
        if any(r < 0 for r in self.time_rates):
            raise ValueError('time_rates must be non-negative')
        if any(int(k) != k or k < 1 for k in (*self.time_powers, *self.widen_powers)):
            raise ValueError('time_powers and widen_powers must be integers >= 1')
        if self.critic_memory < 1 or self.evaluation_period <= 0:
            raise ValueError('critic_memory >= 1 and evaluation_period > 0 required')
        if not 0 < self.rho < 1:
            raise ValueError('rho must be in (0, 1)')
        if min(self.alpha_a, self.alpha_c, self.alpha_d, self.gamma) <= 0:
            raise ValueError('gains and gamma must be positive')
        if self.probing_std < 0 or self.probing_floor < 0 or not 0 < self.probing_decay <= 1:
            raise ValueError('probing noise: std, floor >= 0 and decay in (0, 1]')

    def expanded(self, n: int, m: int) -> ControllerConfig:
        """Return a copy whose M, R, P_T are full, validated, read-only matrices."""
        from dataclasses import replace

        M = _matrix(self.M, n, 'M')
        R = _matrix(self.R, m, 'R')
        P_T = _matrix(self.P_T, n, 'P_T')
        if np.linalg.eigvalsh(R).min() <= 0:
            raise ValueError('R must be positive definite')
        if np.linalg.eigvalsh(M).min() < -1e-12 or np.linalg.eigvalsh(P_T).min() < -1e-12:
            raise ValueError('M and P_T must be positive semi-definite')
        return replace(self, M=M, R=R, P_T=P_T)


@dataclass(frozen=True)
class StepInfo:
    """Diagnostics of the last control step (for /controller/state and benchmarks)."""

    tau: float = 0.0
    """Time-to-go τ = T - (t - t_leg), s."""
    e_c1: float = 0.0
    """Integral Bellman error e_c1 (RRT-QX (19)) before the update."""
    e_c2: float = 0.0
    """Terminal critic error e_c2 before the update (target minus estimate)."""
    e_a: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    """Control-actor error e_a before the update."""
    e_d: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    """Disturbance-actor error e_d before the update (robust)."""
    probing: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    """Probing noise added to the control output, N."""
