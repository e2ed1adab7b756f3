"""Regression rows of the integral Bellman equation (e_c1) and the terminal condition (e_c2).

For the actors' policy (û = Ŵaᵀ(φ(τ) ⊗ x̄), d̂ = Ŵdᵀ(φ(τ) ⊗ x̄)) and samples taken with
*any* applied input (u, d held over [t - Δt, t]), RRT-QX (19) / ACC §IV-A read

    e_c1 = θᵀσ + k,   σ = φ(τ1) ⊗ b(Û1) - φ(τ0) ⊗ b(Û0) - ∫ φ ⊗ (x̄ e_uᵀ, x̄ e_dᵀ) dτ,
    k = Q̂_fixed(Û1) - Q̂_fixed(Û0) + ∫ r(x̄, û, d̂) dτ,

with Û = (x̄, û, d̂) the policy actions, e_u = u - û, e_d = d - d̂ the probing, θ the learned
critic weights (pairs that involve x̄) and Q̂_fixed the part fixed by the cost
(Q̂_uu = R, Q̂_ud = 0, Q̂_dd = -γ²I). The ∫ terms are trapezoids over the two samples with
the held input (error O(Δt³) per step). The terminal condition Q̂(x̄, û(0); τ = 0) =
½x̄ᵀP(T)x̄ gives e_c2 = -(θᵀσ_f + k_f) at every sampled x̄. All functions work on batches
(leading axis = samples).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .basis import QuadraticBasis, TimeBasis

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Policy:
    """The actors' weights and what the rows need of the cost."""

    Wa: Array
    """(L n) x m control-actor weights."""
    Wd: Array
    """(L n) x q disturbance-actor weights (q = 0 in the nominal variant)."""
    M: Array
    R: Array
    P_T: Array
    gamma: float
    time_basis: TimeBasis


def _features(phi: Array, x: Array) -> Array:
    """φ(τ) ⊗ x̄ for a batch: (N, L) and (N, n) -> (N, L n)."""
    return (phi[:, :, None] * x[:, None, :]).reshape(len(x), -1)


def _policy_U(pol: Policy, phi: Array, x: Array) -> tuple[Array, Array, Array]:
    z = _features(phi, x)
    u = z @ pol.Wa
    d = z @ pol.Wd
    return np.hstack([x, u, d]), u, d


def _running_cost(pol: Policy, x: Array, u: Array, d: Array) -> Array:
    r = np.einsum('ni,ij,nj->n', x, pol.M, x) + np.einsum('ni,ij,nj->n', u, pol.R, u)
    return 0.5 * (r - pol.gamma**2 * np.einsum('ni,ni->n', d, d))


def bellman_rows(basis: QuadraticBasis, pol: Policy, fixed_w: Array, dt: float,
                 tau0: Array, x0: Array, tau1: Array, x1: Array, u: Array, d: Array
                 ) -> tuple[Array, Array, Array, Array]:
    """Rows (σ, k) of e_c1 and (σ_f, k_f) of the terminal error for N samples.

    Returns
    -------
    tuple of numpy.ndarray
        σ (N, L p_free), k (N,), σ_f (N, L p_free), k_f (N,). The critic errors are
        e_c1 = σθ + k and e_c2 = -(σ_f θ + k_f).
    """
    n, m, q = basis.n, basis.m, basis.q
    phi0 = pol.time_basis.batch(tau0)
    phi1 = pol.time_basis.batch(tau1)
    U0, u0, d0 = _policy_U(pol, phi0, x0)
    U1, u1, d1 = _policy_U(pol, phi1, x1)
    b0 = U0[:, basis.rows] * U0[:, basis.cols]
    b1 = U1[:, basis.rows] * U1[:, basis.cols]
    free, fixed = basis.free, basis.fixed
    sig = phi1[:, :, None] * b1[:, None, free] - phi0[:, :, None] * b0[:, None, free]
    h = 0.5 * dt
    xu = np.searchsorted(free, basis.xu)
    corr_u = (phi0[:, :, None] * (x0[:, :, None] * (u - u0)[:, None, :]).reshape(len(x0), 1, n * m)
              + phi1[:, :, None] * (x1[:, :, None] * (u - u1)[:, None, :]).reshape(len(x1), 1, n * m))
    sig[:, :, xu] -= h * corr_u
    if q:
        xd = np.searchsorted(free, basis.xd)
        corr_d = (phi0[:, :, None] * (x0[:, :, None] * (d - d0)[:, None, :]).reshape(len(x0), 1, n * q)
                  + phi1[:, :, None] * (x1[:, :, None] * (d - d1)[:, None, :]).reshape(len(x1), 1, n * q))
        sig[:, :, xd] -= h * corr_d
    k = (b1[:, fixed] - b0[:, fixed]) @ fixed_w
    k += h * (_running_cost(pol, x0, u0, d0) + _running_cost(pol, x1, u1, d1))
    phi_end = np.repeat(pol.time_basis.batch(np.zeros(1)), len(x1), axis=0)
    Uf, _, _ = _policy_U(pol, phi_end, x1)
    bf = Uf[:, basis.rows] * Uf[:, basis.cols]
    sig_f = phi_end[:, :, None] * bf[:, None, free]
    k_f = bf[:, fixed] @ fixed_w - 0.5 * np.einsum('ni,ij,nj->n', x1, pol.P_T, x1)
    N = len(x0)
    return sig.reshape(N, -1), k, sig_f.reshape(N, -1), k_f
