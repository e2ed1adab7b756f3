"""Critic and actor bases: the half-vectorised Kronecker basis and the time basis of τ.

The critic of RRT-QX (15) is Q̂ = Ŵcᵀ ν(τ) (U ⊗ U). Here ν(τ)(U ⊗ U) is realised as
φ(τ) ⊗ b(U): ``b(U)`` holds U_i U_j for i <= j (the half-vectorised Kronecker product)
and ``φ(τ) = [exp(-λ_0 τ), ..., exp(-λ_{E-1} τ), (τ/T)^k_1, ...]`` with λ_0 = 0 is a
time basis of the time-to-go τ = T - t (:class:`TimeBasis`). The weight of the pair (i, j) is w_ij, so that
``Q̂ = Σ w_ij U_i U_j = ½ Uᵀ Q̄ U`` with Q̄_ii = 2 w_ii and Q̄_ij = w_ij (i != j).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TimeBasis:
    """φ(τ) of the time-to-go τ, s: exponentials exp(-λ_l τ), then powers (τ / T)^k.

    The exponentials describe values that settle (a stabilising policy's); the powers
    describe values that keep growing over the horizon (a policy that leaves the robot
    away from its target accrues cost linearly in τ: the zero policy on a plant that
    is not stable by itself). The first function is the constant (λ_0 = 0).
    """

    rates: tuple[float, ...]
    """λ_l, 1/s."""
    powers: tuple[int, ...] = ()
    """k >= 1 of the polynomial functions (τ / T)^k."""
    horizon: float = 1.0
    """T, s, that scales the polynomial functions."""

    @property
    def size(self) -> int:
        """L, the number of time functions."""
        return len(self.rates) + len(self.powers)

    def __call__(self, tau: float) -> Array:
        """Evaluate φ(τ); τ is clipped at 0 (past the horizon the terminal critic is used)."""
        return self.batch(np.array([tau], dtype=float))[0]

    def batch(self, taus: Array) -> Array:
        """φ at every τ of ``taus``: (N,) -> (N, L)."""
        t = np.maximum(np.asarray(taus, dtype=float), 0.0)[:, None]
        exps = np.exp(-t * np.asarray(self.rates, dtype=float))
        if not self.powers:
            return exps
        return np.hstack([exps, (t / self.horizon) ** np.asarray(self.powers, dtype=float)])


class QuadraticBasis:
    """Half-vectorised Kronecker basis b(U) of U = (x̄, u, d) and the block layout of Q̄.

    Parameters
    ----------
    n, m, q
        Dimensions of the state, control and disturbance (q = 0 in the nominal variant).
    """

    def __init__(self, n: int, m: int, q: int = 0) -> None:
        self.n, self.m, self.q = n, m, q
        self.dim = n + m + q
        rows, cols = np.triu_indices(self.dim)
        self.rows, self.cols = rows, cols
        self.size = len(rows)
        """p = N(N+1)/2 with N = n + m + q."""
        free = rows < n  # every pair that involves the state (xx, xu, xd blocks)
        self.free = np.flatnonzero(free)
        """Indices of the learned pairs; the uu, ud, dd blocks are fixed from the cost."""
        self.fixed = np.flatnonzero(~free)
        self.xu = np.flatnonzero(free & (cols >= n) & (cols < n + m))
        """Pair indices of the Q_xu block, ordered (x_i, u_j) row-major in (i, j)."""
        self.xd = np.flatnonzero(free & (cols >= n + m))

    def __call__(self, U: Array) -> Array:
        """b(U) = (U_i U_j)_{i<=j}."""
        return U[self.rows] * U[self.cols]

    def fixed_weights(self, R: Array, gamma: float | None) -> Array:
        """Weights of the fixed blocks, Q̂_uu = R, Q̂_ud = 0, Q̂_dd = -γ² I (ACC (12))."""
        Qbar = np.zeros((self.dim, self.dim))
        n, m = self.n, self.m
        Qbar[n:n + m, n:n + m] = R
        if self.q:
            assert gamma is not None
            Qbar[n + m:, n + m:] = -gamma**2 * np.eye(self.q)
        return self.weights_of(Qbar)[self.fixed]

    def weights_of(self, Qbar: Array) -> Array:
        """vech-style weights w with Σ w_ij U_i U_j = ½ Uᵀ Q̄ U."""
        w = Qbar[self.rows, self.cols].copy()
        w[self.rows == self.cols] *= 0.5
        return w

    def matrix_of(self, w: Array) -> Array:
        """Inverse of :meth:`weights_of`: the symmetric Q̄ of a full weight vector."""
        Qbar = np.zeros((self.dim, self.dim))
        Qbar[self.rows, self.cols] = w
        Qbar[self.cols, self.rows] = w
        Qbar[np.diag_indices(self.dim)] *= 2.0
        return Qbar

    def cross_block(self, w_free_block: Array, which: str) -> Array:
        """Q̂_ux (m x n) or Q̂_dx (q x n) from learned weights indexed like ``free``.

        ``w_free_block`` is a full-length pair vector (zeros elsewhere are fine).
        """
        idx = self.xu if which == 'u' else self.xd
        width = self.m if which == 'u' else self.q
        return w_free_block[idx].reshape(self.n, width).T
