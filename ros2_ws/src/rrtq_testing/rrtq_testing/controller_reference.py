"""Ground truth for the controller: true plants, Riccati solutions, exact simulation.

Only the tests and the benchmarks know A, B, F; the controller never does. Written apart
from the simulator's :mod:`rrtq_sim.riccati` and the controller, and checked against
independent facts (the algebraic Riccati equation, the game bound) by
``rrtq_controller/test/test_reference.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp
from scipy.linalg import expm

Array = NDArray[np.float64]
MAXWELL_SLIP_F = np.array([[0.0], [0.0], [-1.0], [1.0]])


def rover(mass: float = 40.0, stiffness: float = 20.0, damping: float = 45.0) -> tuple[Array, Array]:
    """The rover (RRT-QX (26)): A, B of the mass-spring-damper in x and y."""
    k, c, m = stiffness / mass, damping / mass, mass
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [-k, 0, -c, 0], [0, -k, 0, -c]], dtype=float)
    B = np.array([[0, 0], [0, 0], [1 / m, 0], [0, 1 / m]], dtype=float)
    return A, B


def riccati(A: Array, B: Array, M: Array, R: Array, P_T: Array, T: float,
            F: Array | None = None, gamma: float | None = None) -> Callable[[float], Array]:
    """P(τ) of the finite-horizon (game) Riccati equation, τ = T - t the time-to-go.

    RRT-QX (9): -Ṗ = M + PA + AᵀP - PBR⁻¹BᵀP; with F, γ the game Riccati equation
    ACC (8) adds + γ⁻² PFFᵀP. Integrated backward from P(T) = P_T with solve_ivp.
    Raises ``FloatingPointError`` on a finite escape within [0, T].
    """
    n = A.shape[0]
    S = B @ np.linalg.solve(R, B.T)
    if F is not None:
        assert gamma is not None
        S = S - gamma**-2 * F @ F.T

    def rhs(_tau: float, p: Array) -> Array:
        P = p.reshape(n, n)
        return (M + P @ A + A.T @ P - P @ S @ P).ravel()

    def blowup(_tau: float, p: Array) -> float:
        return 1e8 - float(np.abs(p).max())
    blowup.terminal = True  # type: ignore[attr-defined]

    sol = solve_ivp(rhs, (0.0, T), P_T.ravel(), rtol=1e-10, atol=1e-10, dense_output=True,
                    events=blowup)
    if sol.status != 0:
        raise FloatingPointError('finite escape of the Riccati equation')

    def P(tau: float) -> Array:
        Pm = sol.sol(min(max(tau, 0.0), T)).reshape(n, n)
        return 0.5 * (Pm + Pm.T)
    return P


def improved_gain(A: Array, B: Array, M: Array, R: Array, P_T: Array, T: float,
                  gain: Callable[[float], Array]) -> Callable[[float], Array]:
    """τ -> R⁻¹BᵀP^K(τ): the greedy (Kleinman) improvement of the policy u = -K(τ)x̄.

    P^K is the policy's value kernel, from the Lyapunov equation
    dP/dτ = M + KᵀRK + P(A - BK) + (A - BK)ᵀP, P(0) = P_T; the greedy gain of the policy's
    own Q-function is what a critic that evaluates the policy proposes.
    """
    n = A.shape[0]

    def rhs(tau: float, p: Array) -> Array:
        P, K = p.reshape(n, n), gain(tau)
        Acl = A - B @ K
        return (M + K.T @ R @ K + P @ Acl + Acl.T @ P).ravel()

    sol = solve_ivp(rhs, (0.0, T), P_T.ravel(), rtol=1e-10, atol=1e-10, dense_output=True)
    return lambda tau: np.linalg.solve(R, B.T @ sol.sol(tau).reshape(n, n))


def game_gamma_bound(A: Array, B: Array, M: Array, R: Array, P_T: Array, T: float, F: Array,
                     lo: float = 0.1, hi: float = 100.0, iters: int = 22) -> float:
    """Smallest γ for which the game Riccati equation has a solution on [0, T] (bisection)."""
    for _ in range(iters):
        mid = np.sqrt(lo * hi)
        try:
            riccati(A, B, M, R, P_T, T, F, mid)
            hi = mid
        except FloatingPointError:
            lo = mid
    return hi


def zoh(A: Array, B: Array, dt: float) -> tuple[Array, Array]:
    """Exact zero-order-hold discretisation via the matrix exponential."""
    n, m = B.shape
    E = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * dt)
    return E[:n, :n], E[:n, n:]


def zoh_cost(A: Array, B: Array, Qc: Array, dt: float) -> Array:
    """Exact ∫_0^Δt zᵀ Qc z for z = (x, w) with w held: zᵀ Qd z (Van Loan's method)."""
    k = A.shape[0] + B.shape[1]
    Az = np.zeros((k, k))
    Az[:A.shape[0], :A.shape[0]] = A
    Az[:A.shape[0], A.shape[0]:] = B
    E = expm(np.block([[-Az.T, Qc], [np.zeros((k, k)), Az]]) * dt)
    Phi = E[k:, k:]
    Qd = Phi.T @ E[:k, k:]
    return 0.5 * (Qd + Qd.T)


@dataclass
class Plant:
    """A true LTI plant ẋ = Ax + Bu + Fd, simulated exactly per Δt (u, d held)."""

    A: Array
    B: Array
    dt: float
    F: Array = field(default_factory=lambda: np.zeros((4, 0)))

    def __post_init__(self) -> None:
        G = np.hstack([self.B, self.F])
        self.Ad, self.Gd = zoh(self.A, G, self.dt)

    def step(self, x: Array, u: Array, d: Array | None = None) -> Array:
        w = u if d is None or self.F.shape[1] == 0 else np.concatenate([u, d])
        return self.Ad @ x + self.Gd[:, :w.size] @ w


@dataclass
class LegRecord:
    """What one leg did: its start state, cost, and the gain error along the way."""

    x0: Array
    cost: float
    optimum: float
    gain_error: float
    steps: int
    reached: bool

    @property
    def cost_ratio(self) -> float:
        return self.cost / self.optimum


class Diverged(RuntimeError):
    """The closed loop blew up; ``records`` holds the legs completed before."""

    def __init__(self, leg: int, records: list[LegRecord]) -> None:
        super().__init__(f'closed loop diverged on leg {leg}')
        self.leg, self.records = leg, records


def random_legs(rng: np.random.Generator, count: int, lo: float = 3.0, hi: float = 8.0) -> list[Array]:
    """Leg displacement vectors (2-D) with random directions and lengths in [lo, hi] m."""
    ang = rng.uniform(0, 2 * np.pi, count)
    length = rng.uniform(lo, hi, count)
    return [np.array([np.cos(a), np.sin(a)]) * r for a, r in zip(ang, length)]


def run_legs(ctrl, A: Array, B: Array, M: Array, R: Array, P_T: Array, T: float, dt: float,
             legs: list[Array], rho: float, F: Array | None = None,
             disturbance: Callable[[float, Array], Array] | None = None,
             gamma: float | None = None, carry_velocity: bool = True) -> list[LegRecord]:
    """Drive the controller through consecutive legs; score each against the Riccati optimum.

    The state relative to each new target keeps the robot's velocity (a real waypoint
    switch). A leg ends at D <= ρ D0 or at T. Its cost is the exact running cost (plus
    -γ²‖d‖² when ``gamma`` is given) over the leg plus the optimal cost-to-go
    ½ x̄ᵀ P(τ_end) x̄ from where it ended; the optimum is ½ x̄0ᵀ P(T) x̄0. The gain error
    is the mean over the leg's steps of ‖K̂(τ) - K(τ)‖ / ‖K(τ)‖ (Frobenius).
    ``disturbance(tau, x)`` is applied through F; without it and with a robust
    controller, the controller's own d̂ is applied.
    """
    n, m = B.shape
    Fm = np.zeros((n, 0)) if F is None else F
    plant = Plant(A, B, dt, Fm)
    Pf = riccati(A, B, M, R, P_T, T, F, gamma) if gamma is not None else riccati(A, B, M, R, P_T, T)
    q = Fm.shape[1]
    Qc = np.zeros((n + m + q, n + m + q))
    Qc[:n, :n], Qc[n:n + m, n:n + m] = M, R
    if gamma is not None:
        Qc[n + m:, n + m:] = -gamma**2 * np.eye(q)
    Qd = zoh_cost(A, np.hstack([B, Fm]), Qc, dt)
    records: list[LegRecord] = []
    v = np.zeros(n - 2)
    t = 0.0
    for i, disp in enumerate(legs):
        try:
            with np.errstate(over='raise', invalid='raise'):
                rec, x, t = _one_leg(ctrl, plant, Pf, Qd, disp, v, t, T, dt, rho, R, B, q, disturbance,
                                     carry_velocity)
        except (FloatingPointError, OverflowError, np.linalg.LinAlgError):
            raise Diverged(i, records) from None
        records.append(rec)
        v = x[2:]
    return records


def _one_leg(ctrl, plant, Pf, Qd, disp, v, t, T, dt, rho, R, B, q, disturbance, carry_velocity):
    x = np.concatenate([-disp, v if carry_velocity else np.zeros_like(v)])
    x0 = x.copy()
    ctrl.start_leg(x, t)
    D0 = float(np.linalg.norm(x))
    cost, errs, k, reached = 0.0, [], 0, False
    d_prev = None  # the disturbance that acted over the last Δt, as /disturbance reports it
    while True:
        tau = T - k * dt
        if np.linalg.norm(x) <= rho * D0:
            reached = True
            break
        if tau <= 1e-9:
            break
        u = ctrl.step(t, x) if d_prev is None else ctrl.step(t, x, d_prev)
        K = np.linalg.solve(R, B.T @ Pf(tau))
        errs.append(np.linalg.norm(ctrl.gain(tau) - K) / np.linalg.norm(K))
        if q:
            d = disturbance(tau, x) if disturbance is not None else ctrl.d_hat
        else:
            d = np.zeros(0)
        z = np.concatenate([x, u, d])
        cost += 0.5 * float(z @ Qd @ z)
        x = plant.step(x, u, d if q else None)
        d_prev = d if q and disturbance is not None else None
        t += dt
        k += 1
    tau_end = T - k * dt
    cost += 0.5 * float(x @ Pf(tau_end) @ x)
    opt = 0.5 * float(x0 @ Pf(T) @ x0)
    return LegRecord(x0, cost, opt, float(np.mean(errs)) if errs else np.nan, k, reached), x, t
