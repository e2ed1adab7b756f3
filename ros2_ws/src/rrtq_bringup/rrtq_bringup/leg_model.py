"""The true leg problem of a recorded run: step matrices, exact running cost, Riccati.

The model behind :mod:`rrtq_bringup.leg_table` (see its module doc for the method): for
one affine offset c of the leg (0 unless the spring pulls towards the world origin), the
Van Loan matrices of one held step and the finite-horizon Riccati solution of the true
plant with the controller's weights; and the time basis the actor weights were recorded on.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm

from rrtq_bringup.scenario import Scenario
from rrtq_controller.basis import TimeBasis
from rrtq_controller.config import ControllerConfig
from rrtq_sim.riccati import solve_riccati

__all__ = ['LegModel', 'time_basis_of']

Array = NDArray[np.float64]


def time_basis_of(data: Any, horizon: float) -> TimeBasis:
    """The controller's time basis as recorded in /controller/state (its defaults if absent)."""
    if not len(getattr(data, 'time_rates', [])):
        default = ControllerConfig()
        return TimeBasis(default.time_rates, default.time_powers, horizon)
    rates = tuple(float(r) for r in data.time_rates)
    powers = tuple(int(k) for k in getattr(data, 'time_powers', []))
    return TimeBasis(rates, powers, horizon)


def _van_loan(G: Array, Qc: Array, dt: float) -> Array:
    """Q_d with ∫_0^dt zᵀQc z = z0ᵀ Q_d z0 for ż = G z (Van Loan 1978)."""
    k = G.shape[0]
    E = expm(np.block([[-G.T, Qc], [np.zeros((k, k)), G]]) * dt)
    Qd = E[k:, k:].T @ E[:k, k:]
    return 0.5 * (Qd + Qd.T)


class LegModel:
    """The true leg problem for one affine offset c: step matrices, costs, Riccati."""

    def __init__(self, sc: Scenario, c: Array) -> None:
        A, B = np.asarray(sc.plant.A), np.asarray(sc.plant.B)
        F = np.asarray(sc.disturbance.F)
        ctl = sc.controller
        n, m, q = A.shape[0], B.shape[1], F.shape[1]
        self.n, self.m, self.q = n, m, q
        self.M, self.R = np.asarray(ctl.M), np.asarray(ctl.R)
        self.affine = bool(np.any(c != 0.0))
        k = n + m + q + 1
        G = np.zeros((k, k))
        G[:n, :n], G[:n, n:n + m], G[:n, n + m:n + m + q], G[:n, -1] = A, B, F, c
        self.G = G
        Qc = np.zeros((k, k))
        Qc[:n, :n], Qc[n:n + m, n:n + m] = self.M, self.R
        self.Qc = Qc
        self._step: dict[int, tuple[Array, Array]] = {}
        self.B, self.T = B, ctl.horizon
        if self.affine:
            Az = np.zeros((n + 1, n + 1))
            Az[:n, :n], Az[:n, n] = A, c
            Bz = np.vstack([B, np.zeros((1, m))])
            Mz = np.zeros((n + 1, n + 1))
            Mz[:n, :n] = self.M
            PTz = np.zeros((n + 1, n + 1))
            PTz[:n, :n] = ctl.P_T
            self.riccati = solve_riccati(Az, Bz, Mz, self.R, PTz, ctl.horizon)
        else:
            self.riccati = solve_riccati(A, B, self.M, self.R, ctl.P_T, ctl.horizon)

    def step_matrices(self, dt: float) -> tuple[Array, Array]:
        """(E, Q_d): z_k+1 = E z_k and ½ z_kᵀ Q_d z_k = the step's running cost."""
        key = int(round(dt * 1e9))
        if key not in self._step:
            E = expm(self.G * dt)
            self._step[key] = (E, 0.5 * _van_loan(self.G, self.Qc, dt))
        return self._step[key]

    def step(self, x_bar: Array, u: Array, d: Array, dt: float) -> tuple[float, Array]:
        """One step with u and d held: its running cost and the state it ends in."""
        E, Qd = self.step_matrices(dt)
        z = np.concatenate([x_bar, u, d, [1.0]])
        return float(z @ Qd @ z), (E @ z)[:self.n]

    def value(self, x_bar: Array, tau: float) -> float:
        """½ zᵀ P(τ) z, the optimal cost-to-go at time-to-go τ."""
        z = np.append(x_bar, 1.0) if self.affine else x_bar
        return 0.5 * float(z @ self.riccati.P(tau) @ z)

    def policy(self, x_bar: Array, tau: float) -> Array:
        """The optimal force at x̄ with time-to-go τ, −R⁻¹BᵀP(τ)z (the affine form's too)."""
        z = np.append(x_bar, 1.0) if self.affine else x_bar
        return -self.riccati.gain(tau) @ z

    def gain(self, tau: float) -> Array:
        """R⁻¹BᵀP_xx(τ), the linear part of the optimal feedback (m x n)."""
        P = self.riccati.P(tau)[:self.n, :self.n]
        return np.linalg.solve(self.R, self.B.T @ P)

