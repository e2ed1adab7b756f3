"""What the learned weights say: gains, value kernels, the critic's greedy policy.

A read-only view shared by :class:`rrtq_controller.q_learning.QLearningController`
(which learns the weights) and the readers of its state: Ŵa, Ŵd on the time basis
φ(τ) ⊗ I_n of the actors, θ of the critic on φ(τ) ⊗ b(U) (see :mod:`basis`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm

from .basis import QuadraticBasis, TimeBasis
from .config import ControllerConfig
from .critic import Critic, Fit
from .guard import FALSE_ALARM

Array = NDArray[np.float64]


def _features(phi: Array, x: Array) -> Array:
    """The features z = φ(τ) ⊗ x̄ (what μ(τ)x̄ is with μ = φ ⊗ I_n)."""
    return (phi[:, None] * x[None, :]).ravel()


class WeightReadout:
    """Gains and kernels of the weights of a Q-learning controller (a mixin)."""

    config: ControllerConfig
    n: int
    m: int
    q: int
    robust: bool
    gamma: float
    time_basis: TimeBasis
    basis: QuadraticBasis
    critic: Critic
    _Wa: Array
    _Wd: Array
    _Rinv: Array
    _fixed_w: Array
    _free_xu: NDArray[np.intp]
    _free_xd: NDArray[np.intp]

    def policy_value_kernel(self, tau: float, theta: Array | None = None,
                            Wa: Array | None = None, Wd: Array | None = None) -> Array:
        """P̂^π(τ) of a policy's value V̂^π = Q̂(x̄, û, d̂) = ½x̄ᵀP̂^πx̄ (û = -K̂x̄, d̂ = L̂x̄).

        By default the actors' own policy under the current critic; ``theta``, ``Wa``,
        ``Wd`` give another critic fit and the policy it was fitted for.
        """
        phi = self.time_basis(tau)
        theta = self.critic.theta if theta is None else theta
        Q = self.basis.matrix_of(self._full_weights(phi, theta))
        n = self.n
        K = self.gain(tau, self._Wa if Wa is None else Wa)
        rows = [np.eye(n), -K]
        if self.q:
            rows.append(self.disturbance_gain(tau, self._Wd if Wd is None else Wd))
        G = np.vstack(rows)
        P = G.T @ Q @ G
        return 0.5 * (P + P.T)

    def policy_actions(self, tau: float, x: Array, Wa: Array | None = None,
                       Wd: Array | None = None) -> Array:
        """U = (x̄, û, d̂) of a policy at x̄ and τ (by default the actors'): Q̂(U) is its value."""
        parts = [x, -self.gain(tau, self._Wa if Wa is None else Wa) @ x]
        if self.q:
            parts.append(self.disturbance_gain(tau, self._Wd if Wd is None else Wd) @ x)
        return np.concatenate(parts)

    def value_kernel(self, tau: float) -> Array:
        """P̂(τ) of V̂ = min_u max_d Q̂ = ½x̄ᵀP̂x̄: Q̂_xx - Q̂_xuR⁻¹Q̂_ux (+ γ⁻² Q̂_xdQ̂_dx)."""
        phi = self.time_basis(tau)
        Q = self.basis.matrix_of(self._full_weights(phi))
        n = self.n
        Qux = self._cross(phi, 'u')
        P = Q[:n, :n] - Qux.T @ self._Rinv @ Qux
        if self.robust:
            Qdx = self._cross(phi, 'd')
            P = P + self.gamma**-2 * Qdx.T @ Qdx
        return 0.5 * (P + P.T)

    def _greedy(self, which: str) -> Array:
        """Per time function, Q̂_ux (m x n) or Q̂_dx (q x n) stacked as (m|q) x (L n)."""
        L, n = self.time_basis.size, self.n
        idx = self._free_xu if which == 'u' else self._free_xd
        width = self.m if which == 'u' else self.q
        blocks = self.critic.theta.reshape(L, -1)[:, idx].reshape(L, n, width)
        Q = np.concatenate([blk.T for blk in blocks], axis=1)
        return self._Rinv @ Q if which == 'u' else Q

    # ------------------------------------------------------------ readouts

    def gain(self, tau: float, Wa: Array | None = None) -> Array:
        """Learned feedback gain K̂(τ) (m x n) of the control actor: û = -K̂(τ) x̄."""
        phi = self.time_basis(tau)
        W = self._Wa if Wa is None else Wa
        return -np.einsum('l,lij->ji', phi, W.reshape(-1, self.n, self.m))

    def critic_gain(self, tau: float) -> Array:
        """Greedy gain of the critic, Q̂_uu⁻¹ Q̂_ux(τ) (what the actor converges to)."""
        return self._Rinv @ self._cross(self.time_basis(tau), 'u')

    def disturbance_gain(self, tau: float, Wd: Array | None = None) -> Array:
        """Learned disturbance gain L̂(τ) (q x n) of the disturbance actor: d̂ = L̂(τ) x̄."""
        phi = self.time_basis(tau)
        W = self._Wd if Wd is None else Wd
        return np.einsum('l,lij->ji', phi, W.reshape(-1, self.n, self.q))

    def q_matrix(self, tau: float) -> Array:
        """The estimated kernel Q̄̂(τ) of Q̂ = ½ Uᵀ Q̄̂ U (RRT-QX (13), ACC (12))."""
        return self.basis.matrix_of(self._full_weights(self.time_basis(tau)))

    @property
    def critic_weights(self) -> Array:
        """Ŵc: all critic weights, time function by time function (fixed blocks included)."""
        L, b = self.time_basis.size, self.basis
        W = np.zeros((L, b.size))
        W[:, b.free] = self.critic.theta.reshape(L, -1)
        W[0, b.fixed] = self._fixed_w
        return W.ravel()

    @property
    def actor_weights(self) -> Array:
        """Ŵa, (L n) x m, flattened."""
        return self._Wa.ravel().copy()

    @property
    def disturbance_weights(self) -> Array:
        """Ŵd, (L n) x q, flattened (empty in the nominal variant)."""
        return self._Wd.ravel().copy()

    def _full_weights(self, phi: Array, theta: Array | None = None) -> Array:
        w = np.zeros(self.basis.size)
        theta = self.critic.theta if theta is None else theta
        w[self.basis.free] = phi @ theta.reshape(phi.size, -1)
        w[self.basis.fixed] = self._fixed_w
        return w

    def _cross(self, phi: Array, which: str) -> Array:
        """Q̂_ux(τ) (m x n) or Q̂_dx(τ) (q x n) at the time basis value φ(τ)."""
        theta = self.critic.theta.reshape(phi.size, -1)
        idx = self._free_xu if which == 'u' else self._free_xd
        width = self.m if which == 'u' else self.q
        return (phi @ theta[:, idx]).reshape(self.n, width).T

    def _policy_u(self, phi: Array, x: Array) -> Array:
        return self._Wa.T @ _features(phi, x)

    def _policy_sensitivity(self, phi: Array) -> Array:
        """∂u/∂x̄ (m x n) of the actor's force at the time basis value φ(τ): -K̂(τ)."""
        return np.einsum('l,lim->mi', phi, self._Wa.reshape(phi.size, self.n, self.m))

    def _policy_d(self, phi: Array, x: Array) -> Array:
        return self._Wd.T @ _features(phi, x)

    def _negative_value_share(self, theta: Array, Wa: Array, Wd: Array,
                              fit: Fit | None = None) -> float:
        """The negative part of a policy's value under a critic fit, where the data are.

        Every policy's value is positive (M >= 0, P(T) > 0); here (Wa, Wd) under θ, at the
        stored samples: V̂(x̄_i, τ_i) = ½ x̄_iᵀ P̂(τ_i) x̄_i, and the share returned is
        Σ max(-V̂, 0) / Σ |V̂| (1 without data). A disturbance the critic cannot see leaves
        a small one (0.1 %), a critic that has not been identified a large one (90 % on the
        first leg from a zero gain; a few % where a leg enters times-to-go τ that no stored
        sample covers). Positive definiteness of P̂(τ) as a matrix is not asked: the data
        identify some directions (positions) far better than others (velocities, on the
        first legs), and in those the trust region bounds the change instead.

        With ``fit`` (θ's fit, with its spread) only what is negative beyond what noise
        explains counts: V̂_i + z σ_i, σ_i the standard error of V̂_i (linear in θ) and z
        the one-sided normal quantile of :data:`guard.FALSE_ALARM`; a value the noise of
        the data could have made negative is not held against the critic. With exact data
        σ_i is the fit's own (small) misfit and the share is nearly the plain one.
        """
        tau0, x0, *_ = self.critic.window.samples()
        if not len(tau0):
            return 1.0
        phi = self.time_basis.batch(tau0)
        full = np.zeros((len(tau0), self.basis.size))
        full[:, self.basis.free] = phi @ theta.reshape(phi.shape[1], -1)
        full[:, self.basis.fixed] = self._fixed_w
        z = (phi[:, :, None] * x0[:, None, :]).reshape(len(x0), -1)
        U = np.hstack([x0, z @ Wa] + ([z @ Wd] if self.q else []))
        pairs = U[:, self.basis.rows] * U[:, self.basis.cols]
        value = np.einsum('ij,ij->i', full, pairs)
        total = float(np.sum(np.abs(value)))
        if fit is not None and fit.spread is not None:
            g = (phi[:, :, None] * pairs[:, None, self.basis.free]).reshape(len(x0), -1)
            value = value + float(norm.ppf(1.0 - FALSE_ALARM)) * fit.standard_errors(g)
        return float(np.sum(np.maximum(-value, 0.0))) / total if total > 0 else 1.0
