"""Model-free finite-horizon continuous-time Q-learning (RRT-QX §4; robust: ACC 2019 §III-IV).

The controller never sees the plant matrices. Per control period Δt it receives the state
x̄ relative to the leg target and the time t, and answers the force u. Sign convention:
û = Ŵaᵀ μ(τ) x̄ = -K̂(τ) x̄, so :meth:`QLearningController.gain` is comparable with the
Riccati gain R⁻¹BᵀP(τ); the disturbance actor is d̂ = Ŵdᵀ ξ(τ) x̄ = L̂(τ) x̄, comparable
with γ⁻²FᵀP(τ). Here μ(τ) = ξ(τ) = φ(τ) ⊗ I_n with the time basis φ of :mod:`basis`.

Per step (RRT-QX Algorithm 1, lines 12-16): the critic errors e_c1, e_c2 of the last Δt
(:mod:`bellman`, which also documents how the integrals are evaluated from the samples and
the probing-noise correction), the critic law (:mod:`critic`), the actor steps, then the
control with probing noise. Safeguards, all model-free: Q̂_uu = R, Q̂_ud = 0, Q̂_dd = -γ²I
are fixed (the cost's own weights); actor steps are normalised; the actors follow the
critic only while its value kernel is positive definite and roll back otherwise
(:meth:`QLearningController.policy_evaluation`); the first leg only collects data.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .basis import QuadraticBasis, TimeBasis
from .config import ActorLaw, ControllerConfig, StepInfo, Variant
from .bellman import Policy, bellman_rows
from .critic import LeastSquaresCritic, make_critic
from .stability import gain_warnings

Array = NDArray[np.float64]


def _features(phi: Array, x: Array) -> Array:
    """The features z = φ(τ) ⊗ x̄ (what μ(τ)x̄ is with μ = φ ⊗ I_n)."""
    return (phi[:, None] * x[None, :]).ravel()


class QLearningController:
    """Actor/critic Q-learning controller for one robot; weights carry from leg to leg.

    Parameters
    ----------
    config
        Controller parameters; scalar matrices are expanded to n x n / m x m.
    n, m, q
        State, control and disturbance dimensions (q is ignored in the nominal variant).
    rng
        Source of the probing noise.
    """

    def __init__(self, config: ControllerConfig, n: int, m: int, q: int,
                 rng: np.random.Generator) -> None:
        self.config = config.expanded(n, m)
        self.robust = self.config.variant is Variant.ROBUST
        self.gains = self.config.gains
        self.gamma = self.config.gamma if self.robust and self.config.gamma is not None else 0.0
        """Attenuation level γ of the game (0 in the nominal variant: d is empty there)."""
        self.n, self.m, self.q = n, m, (q if self.robust else 0)
        self._rng = rng
        self.time_basis = TimeBasis(self.config.time_rates, self.config.time_powers, self.config.horizon)
        self.basis = QuadraticBasis(n, m, self.q)
        L, b = self.time_basis.size, self.basis
        self._fixed_w = b.fixed_weights(self.config.R, self.gamma if self.robust else None)
        self._free_xu = np.searchsorted(b.free, b.xu)
        self._free_xd = np.searchsorted(b.free, b.xd)
        self.critic = make_critic(np.zeros(L * b.free.size), self.config, n, m, self.q)
        self._Wa = np.zeros((L * n, m))
        if self.config.initial_gain is not None:
            self._Wa[:n] = -np.asarray(self.config.initial_gain, dtype=float).reshape(m, n).T
        self._Wd = np.zeros((L * n, self.q))
        self._Rinv = np.linalg.inv(self.config.R)
        self._safe = (self._Wa.copy(), self._Wd.copy())
        self.leg_index = -1
        self._t0 = 0.0
        self._prev: tuple[float, Array, Array] | None = None
        self._since_eval = 0
        self.critic_trusted = False
        """Whether the actors currently follow the critic (see :meth:`policy_evaluation`)."""
        self._full_legs = 0
        self.widened = False
        """Whether the time basis was widened by ``widen_powers`` (see :meth:`widen_time_basis`)."""
        self._d_out = np.zeros(self.q)
        self._noise_u = np.zeros(m)
        self._noise_d = np.zeros(self.q)
        tc = self.config.probing_correlation
        self._ou = float(np.exp(-self.config.dt / tc)) if tc > 0 else 0.0
        self.info = StepInfo()
        self.warnings: list[str] = gain_warnings(self)

    # ----------------------------------------------------------------- legs
    def start_leg(self, x0_bar: Array, t: float) -> None:
        """Begin a new finite-horizon problem at time t (s) from x̄0 (RRT-QX Alg. 1, l. 6).

        The learned weights are kept: the Q-function depends on x̄, u and τ only.
        """
        del x0_bar  # D0 is the sequencer's business; the critic needs no leg data
        if self.leg_index >= 0:
            ran_out = t - self._t0 >= self.config.horizon - 0.5 * self.config.dt
            self._full_legs = self._full_legs + 1 if ran_out else 0
            c = self.config
            if (self._full_legs >= c.widen_after_legs and c.widen_powers and not self.widened
                    and isinstance(self.critic, LeastSquaresCritic)):
                self.widen_time_basis()
            self.policy_evaluation()
        self.leg_index += 1
        self._t0 = float(t)
        self._prev = None

    def time_to_go(self, t: float) -> float:
        """τ = T - (t - t_leg), s, clipped at 0."""
        return max(self.config.horizon - (t - self._t0), 0.0)

    @property
    def probing_std(self) -> float:
        """Current control probing standard deviation, N (decays per leg)."""
        c = self.config
        return max(c.probing_std * c.probing_decay ** max(self.leg_index, 0), c.probing_floor)

    # ---------------------------------------------------------------- step
    def step(self, t: float, x_bar: Array, d_applied: Array | None = None) -> Array:
        """One control period (RRT-QX Alg. 1, lines 12-16; ACC Alg. 1, lines 8-14).

        Parameters
        ----------
        t
            Current time, s (monotone within a leg).
        x_bar
            State relative to the leg target, x̄(t) = x(t) - x_r.
        d_applied
            Robust variant: the disturbance that acted over [t - Δt, t], if measured;
            by default the controller's own :attr:`d_hat` output is assumed applied.

        Returns
        -------
        numpy.ndarray
            The force u to hold over [t, t + Δt), actor output plus probing noise.
        """
        if self.leg_index < 0:
            self.start_leg(x_bar, t)
        x = np.array(x_bar, dtype=float)  # a copy: it is kept for the next step
        tau = self.time_to_go(t)
        e_c1 = e_c2 = 0.0
        if self._prev is not None:
            measured = d_applied is not None and self.robust
            d_prev = np.asarray(d_applied, dtype=float) if measured else self._d_out
            e_c1, e_c2 = self.critic_update(tau, x, d_prev)
        phi = self.time_basis(tau)  # after the update, which may widen the basis
        e_a = e_d = np.zeros(0)
        if self.leg_index >= self.config.actor_warmup_legs and self.critic_trusted:
            e_a = self.actor_update(phi, x)
            if self.robust:
                e_d = self.disturbance_actor_update(phi, x)
        noise = self._probe(self._noise_u, self.probing_std)
        self._noise_u = noise
        u = self._policy_u(phi, x) + noise
        if self.robust:
            d_std = self.config.disturbance_probing_std * self.config.probing_decay ** self.leg_index
            self._noise_d = self._probe(self._noise_d, d_std)
            self._d_out = self._policy_d(phi, x) + self._noise_d
        self._prev = (tau, x, u)
        self.info = StepInfo(tau=tau, e_c1=e_c1, e_c2=e_c2, e_a=e_a, e_d=e_d, probing=noise)
        return u

    @property
    def d_hat(self) -> Array:
        """Disturbance actor output (with its probing noise) to apply over the next Δt."""
        return self._d_out.copy()

    # ------------------------------------------------------------ learning
    def critic_update(self, tau: float, x: Array, d_applied: Array) -> tuple[float, float]:
        """Critic step from e_c1 (RRT-QX (19); ACC §IV-A) and e_c2 on the last Δt.

        GRADIENT: one Euler step of the normalised law (22) / ACC (21).
        LEAST_SQUARES: the sample is stored and the critic re-solved for the current
        actors every ``evaluation_period`` (policy evaluation, :class:`LeastSquaresCritic`).
        A step past the horizon (the goal's leg keeps station with τ clipped at 0) is no
        sample of the finite-horizon problem and is not learned from: its rows would claim
        Q̂(·, τ = 0) - Q̂(·, τ = 0) = ∫r, against the terminal condition, and pull the critic
        (and the station-keeping gain) away.

        Returns
        -------
        tuple of float
            (e_c1, e_c2) before the update; e_c2 as target minus estimate.
        """
        assert self._prev is not None
        tau0, x0, u_app = self._prev
        one = np.ones(1)
        sig, k, sig_f, k_f = self._rows(tau0 * one, x0[None], tau * one, x[None], u_app[None], d_applied[None])
        theta = self.critic.theta
        e_c1 = float(sig[0] @ theta + k[0])
        e_c2 = -float(sig_f[0] @ theta + k_f[0])
        if tau0 <= 0.0:  # the leg's horizon had passed at the start of this Δt
            return e_c1, e_c2
        if isinstance(self.critic, LeastSquaresCritic):
            self.critic.add_sample(tau0, x0, tau, x, u_app, d_applied)
        else:
            self.critic.update(np.vstack([sig, sig_f]), np.concatenate([k, k_f]))
        self._since_eval += 1
        if self._since_eval * self.config.dt >= self.config.evaluation_period - 1e-9:
            self.policy_evaluation()
        return e_c1, e_c2

    def policy_evaluation(self) -> None:
        """Re-fit the least-squares critic for the current actors; re-check the critic's trust.

        The actors follow the critic only while the value it assigns to their own policy,
        P̂^π(τ) (see :meth:`policy_value_kernel`), is positive definite on [T/2, T] (where
        legs, which end at D <= ρ D0, spend their time; near τ = 0 the time basis fits
        worst): with M >= 0 and P(T) > 0 every policy's value is, so an indefinite kernel
        means the critic has not yet been identified (e.g. from one leg in one direction)
        and its greedy gain must not be followed. When the check fails, the actors are
        rolled back to the last policy that passed it (initially the initial weights).
        This is model-free; without it a first leg's poor fit could destabilise the loop.
        The greedy kernel of :meth:`value_kernel` (min over u of Q̂) is not the test: for a
        poor policy, such as the zero policy on the rover without a spring, Q̂_xuR⁻¹Q̂_ux
        exceeds Q̂_xx and that kernel is indefinite although the fit is right, so learning
        never starts from a zero gain.
        """
        if isinstance(self.critic, LeastSquaresCritic):
            self.critic.evaluate(self._rows)
        self._since_eval = 0
        taus = np.linspace(0.5 * self.config.horizon, self.config.horizon, 6)
        self.critic_trusted = all(np.linalg.eigvalsh(self.policy_value_kernel(t)).min() > 0 for t in taus)
        if self.critic_trusted:
            self._safe = (self._Wa.copy(), self._Wd.copy())
        else:
            self._Wa, self._Wd = self._safe[0].copy(), self._safe[1].copy()

    def widen_time_basis(self) -> None:
        """Append the powers (τ / T)^k of ``widen_powers`` to the time basis, once.

        Called at a leg start after ``widen_after_legs`` legs in a row ran their whole
        horizon without reaching their window: the policy does not bring the robot to
        its targets, so its value keeps growing over the horizon (the zero gain on the
        rover without a spring: linearly in τ), which the exponentials cannot fit.

        The actors' policy is unchanged (zero weights on the new functions); the
        least-squares critic stores raw samples and is re-fitted on the wider basis from
        a zero prior.
        """
        c, n, b = self.config, self.n, self.basis
        powers = c.time_powers + tuple(k for k in c.widen_powers if k not in c.time_powers)
        extra = len(powers) - len(c.time_powers)
        self.time_basis = TimeBasis(c.time_rates, powers, c.horizon)
        # the old fit (of a value it could not represent) is no prior for the new one
        self.critic.theta = np.zeros(self.time_basis.size * b.free.size)

        def pad(W: Array) -> Array:
            return np.vstack([W, np.zeros((extra * n, W.shape[1]))])
        self._Wa, self._Wd = pad(self._Wa), pad(self._Wd)
        self._safe = (pad(self._safe[0]), pad(self._safe[1]))
        self.widened = True

    def policy_value_kernel(self, tau: float) -> Array:
        """P̂^π(τ) of the actors' own value V̂^π = Q̂(x̄, û, d̂) = ½x̄ᵀP̂^πx̄ (û = -K̂x̄, d̂ = L̂x̄)."""
        phi = self.time_basis(tau)
        Q = self.basis.matrix_of(self._full_weights(phi))
        n = self.n
        G = np.vstack([np.eye(n), -self.gain(tau)] + ([self.disturbance_gain(tau)] if self.robust else []))
        P = G.T @ Q @ G
        return 0.5 * (P + P.T)

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

    def _rows(self, *batch: Array) -> tuple[Array, Array, Array, Array]:
        c = self.config
        pol = Policy(self._Wa, self._Wd, c.M, c.R, c.P_T, self.gamma, self.time_basis)
        return bellman_rows(self.basis, pol, self._fixed_w, c.dt, *batch)

    def actor_update(self, phi: Array, x: Array) -> Array:
        """Control-actor step towards the critic's greedy policy, RRT-QX (23).

        e_a = Ŵaᵀ z + Q̂_uu⁻¹ Q̂_ux(τ) x̄ with z = μ(τ)x̄ = φ(τ) ⊗ x̄. GRADIENT: the
        normalised Euler step Ŵa ← Ŵa - α_a Δt z e_aᵀ / (1 + zᵀz); the plain step of (23)
        multiplies the error along z by 1 - α_a Δt ‖z‖², unstable once α_a Δt ‖x̄‖² > 2
        (long legs), normalised the factor stays in (1 - α_a Δt, 1]. WHITENED: see
        :class:`ActorLaw`.
        """
        e_a = self._Wa.T @ _features(phi, x) + self._Rinv @ (self._cross(phi, 'u') @ x)
        target = -self._greedy('u').T
        self._Wa = self._actor_step(self._Wa, target, phi, x, e_a, self.gains.alpha_a)
        return e_a

    def disturbance_actor_update(self, phi: Array, x: Array) -> Array:
        """Disturbance-actor step, ACC (23): e_d = Ŵdᵀ z + Q̂_dd⁻¹ Q̂_dx(τ) x̄, Q̂_dd = -γ² I."""
        e_d = self._Wd.T @ _features(phi, x) - self.gamma ** -2 * (self._cross(phi, 'd') @ x)
        target = self.gamma ** -2 * self._greedy('d').T
        self._Wd = self._actor_step(self._Wd, target, phi, x, e_d, self.gains.alpha_d)
        return e_d

    def _actor_step(self, W: Array, target: Array, phi: Array, x: Array, err: Array, alpha: float) -> Array:
        h = alpha * self.config.dt
        if self.config.actor_law is ActorLaw.WHITENED:
            return W - h * (W - target)
        z = _features(phi, x)
        return W - (h / (1.0 + z @ z)) * np.outer(z, err)

    def _greedy(self, which: str) -> Array:
        """Per time function, Q̂_ux (m x n) or Q̂_dx (q x n) stacked as (m|q) x (L n)."""
        L, n = self.time_basis.size, self.n
        idx = self._free_xu if which == 'u' else self._free_xd
        width = self.m if which == 'u' else self.q
        blocks = self.critic.theta.reshape(L, -1)[:, idx].reshape(L, n, width)
        Q = np.concatenate([blk.T for blk in blocks], axis=1)
        return self._Rinv @ Q if which == 'u' else Q

    # ------------------------------------------------------------ readouts
    def gain(self, tau: float) -> Array:
        """Learned feedback gain K̂(τ) (m x n) of the control actor: û = -K̂(τ) x̄."""
        phi = self.time_basis(tau)
        return -np.einsum('l,lij->ji', phi, self._Wa.reshape(-1, self.n, self.m))

    def critic_gain(self, tau: float) -> Array:
        """Greedy gain of the critic, Q̂_uu⁻¹ Q̂_ux(τ) (what the actor converges to)."""
        return self._Rinv @ self._cross(self.time_basis(tau), 'u')

    def disturbance_gain(self, tau: float) -> Array:
        """Learned disturbance gain L̂(τ) (q x n) of the disturbance actor: d̂ = L̂(τ) x̄."""
        phi = self.time_basis(tau)
        return np.einsum('l,lij->ji', phi, self._Wd.reshape(-1, self.n, self.q))

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

    def set_weights(self, critic: Array | None = None, actor: Array | None = None,
                    disturbance: Array | None = None) -> None:
        """Load learned weights (e.g. saved from a previous run); shapes as the accessors."""
        L, b = self.time_basis.size, self.basis
        if critic is not None:
            self.critic.theta = np.asarray(critic, dtype=float).reshape(L, b.size)[:, b.free].ravel()
        if actor is not None:
            self._Wa = np.asarray(actor, dtype=float).reshape(self._Wa.shape).copy()
        if disturbance is not None:
            self._Wd = np.asarray(disturbance, dtype=float).reshape(self._Wd.shape).copy()

    def check_gains(self) -> list[str]:
        """Warnings where α_a, α_c, α_d violate the stability bounds for the current critic."""
        self.warnings = gain_warnings(self)
        return self.warnings

    # ------------------------------------------------------------- helpers
    def _probe(self, previous: Array, std: float) -> Array:
        """Next probing sample: Ornstein-Uhlenbeck with stationary standard deviation ``std``."""
        a = self._ou
        return a * previous * (std > 0) + np.sqrt(1.0 - a * a) * std * self._rng.standard_normal(previous.size)

    def _full_weights(self, phi: Array) -> Array:
        w = np.zeros(self.basis.size)
        w[self.basis.free] = phi @ self.critic.theta.reshape(phi.size, -1)
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

    def _policy_d(self, phi: Array, x: Array) -> Array:
        return self._Wd.T @ _features(phi, x)
