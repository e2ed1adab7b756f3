"""Policy iteration with a guard: the critic's updates, evaluation, improvement and revert.

The learning half of :class:`rrtq_controller.q_learning.QLearningController` (a mixin, as
:class:`rrtq_controller.readout.WeightReadout` is its reading half): per step the critic
learns from the last Δt (:meth:`PolicyIteration.critic_update`, RRT-QX (19)-(22)); every
``evaluation_period`` and at each leg start it is re-fitted for the actors' policy
(:meth:`PolicyIteration.policy_evaluation`), and its proposal becomes the actors' target
only when it passes the checks of :meth:`PolicyIteration.policy_improvement` (beyond the
papers: :mod:`guard`); a leg that diverges reverts the actors to the last policy that
completed a leg (:meth:`PolicyIteration.revert`).
"""

from __future__ import annotations

from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm

from .bellman import Policy, bellman_rows
from .config import SafeHold
from .critic import Fit, LeastSquaresCritic, fit, residual
from .guard import FALSE_ALARM, Brake, PolicyEvent, Sensing, held_below, trust_step
from .observer import Observer, PushCanceller
from .push_feedforward import PushFeedforward
from .readout import WeightReadout
from .rollout import AwayFrom, Rollout

Array = NDArray[np.float64]


def _misfit(f: Fit) -> str:
    """How a fit's residual reads in a rejection: its misfit, and the noise part taken off."""
    return f'fit residual {f.residual:.3g} (noise {f.noise:.3g}: misfit {f.misfit:.3g})'


class PolicyIteration(WeightReadout):
    """The critic's updates and the guarded policy iteration of a Q-learning controller (a mixin).

    The state it reads and changes is :class:`rrtq_controller.q_learning.QLearningController`'s
    (set up in its constructor; see the attributes' documentation there).
    """

    leg_index: int
    observer: Observer | None
    _rollout_of: Rollout | None
    sensing: Sensing
    critic_trusted: bool
    event_counts: dict[PolicyEvent, int]
    _prev: tuple[float, Array, Array] | None
    _step_id: int
    _since_eval: int
    _steady: Array
    _canceller: PushCanceller | None
    _forward: PushFeedforward | None
    _braking_sense: Sensing
    _target: tuple[Array, Array]
    _initial: tuple[Array, Array]
    _completed: tuple[Array, Array] | None
    _adopted_since: bool
    _spared: bool
    _held: bool
    _full_legs: int
    _braking: bool
    _brake: Brake
    _brake_started: float
    _brake_until: float
    _events: list[tuple[PolicyEvent, str]]

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
        self.critic.window.add_sample(tau0, x0, tau, x, u_app, d_applied, self._step_id)
        if not isinstance(self.critic, LeastSquaresCritic):
            self.critic.update(np.vstack([sig, sig_f]), np.concatenate([k, k_f]))
        self._since_eval += 1
        if self._since_eval * self.config.dt >= self.config.evaluation_period - 1e-9:
            self.policy_evaluation()
        return e_c1, e_c2

    def policy_evaluation(self) -> None:
        """Re-fit the critic for the current actors and let the guard consider its proposal.

        The least-squares critic is re-fitted (the gradient critic's own fit only
        scored); then :meth:`policy_improvement`. ``critic_trusted`` (a diagnostic)
        says whether the critic's value of the actors' own policy passes the guard's
        test (:meth:`_negative_value_share` within ``value_tolerance``).
        """
        if self.observer is not None and self.observer.update():
            window = self.critic.window
            steps = window.steps()
            x0, x1, u, known = self.observer.estimates(steps)
            if self.robust:      # the game's player d: the push; u: the force that acted
                acted = self.observer.acted(steps, known)
                window.estimate(x0, x1, acted, known, u - acted)
            else:
                window.estimate(x0, x1, u, known)
            assert self.observer.model is not None
            model = self.observer.model
            self.sensing.dead_steps = self._braking_sense.dead_steps = model.delay
            velocity_rows = model.gamma[2:2 + self.m]
            self.sensing.step_gain = self._braking_sense.step_gain = (
                float(np.linalg.norm(velocity_rows, 2)) if velocity_rows.size else 0.0)
            # the last second's steady push, where it stands out of the noise (guard.KeepOff)
            mean, error = self.observer.steady_push(max(int(round(1.0 / self.config.dt)), 2))
            z = float(norm.ppf(1.0 - FALSE_ALARM / 2))
            self._steady = np.where(np.abs(mean) > z * error, mean, 0.0)
            if self._canceller is not None:     # what of the push can be predicted, and how
                self._canceller.fit(self.observer.pushes(), model.delay + 1)
            if self._forward is not None:       # its internal model and LQ gain
                self._forward.fit(model.phi, model.gamma, self.observer.pushes(),
                                  self.observer.read_noise(), model.delay + 1)
        if isinstance(self.critic, LeastSquaresCritic):
            self.critic.evaluate(self._rows)
        else:
            self.critic.residual = residual(self._rows, self.critic.window, self.critic.theta)
            self.critic.last = Fit(self.critic.theta, self.critic.residual)
        self._since_eval = 0
        share = self._negative_value_share(self.critic.theta, self._Wa, self._Wd, self.critic.last)
        self.critic_trusted = share <= self.config.value_tolerance
        self.policy_improvement()

    def policy_improvement(self) -> None:
        """Guarded policy improvement (beyond the papers).

        The critic's proposal becomes the actors' target only when it passes every
        check, in this order.

        1. The critic that proposes it is trusted (:meth:`policy_evaluation`) and its fit
           explains the data: relative residual <= ``max_fit_residual``.
        2. Coverage: below the times-to-go the stored samples cover (their
           ``coverage_quantile``), the proposal's gain is held at its value at that edge
           (:func:`guard.held_below`): the critic is not followed where it extrapolates.
        3. Trust region: the step from the current target toward the critic's greedy
           weights is shortened until ‖ΔK̂(τ)‖ <= ``trust_growth`` max(‖K̂(τ)‖, K_floor)
           on a grid of τ (every direction of the gain, not only those the data visit),
           K_floor being the probing scale (or the RMS force applied in the data) over
           the RMS size of the stored states; and until the force it adds on the stored
           states stays within the force limit (:func:`guard.trust_step`).
        4. The proposed policy, evaluated off-policy on the same data (a least-squares fit
           of its own Q-function, :func:`critic.fit`), fits as well as in 1 and its value
           is positive on the data: a negative share of at most ``value_tolerance``, or
           no more than the current target's own under the critic (where a leg enters
           times-to-go no sample covers, neither is identified there, and the status quo
           is not the safer choice). Once a policy has completed a leg (the status quo
           works), more is asked: the proposal's value kernel P̂(τ) must be positive
           definite as a matrix on [T/2, T] (every direction of x̄ identified, not only
           those the data visit), as the previous controller asked of its critic before
           following it at all; but not while the last ``widen_after_legs`` legs or more in
           a row ran their horizon without reaching their window (the status quo no longer
           works: on the 110 kg rover a weak policy crept 1 m in 165 s, leg after leg, while
           the critic, fitted to data with little excitation left, failed this test 97
           times). If not, the step is halved, up to three times.

        Nothing is adopted during the first ``actor_warmup_legs`` legs nor for the rest of
        a leg that reverted. Each adoption and rejection is recorded (``StepInfo``).
        """
        c, window = self.config, self.critic.window
        if self.leg_index < c.actor_warmup_legs or self._held or window.count == 0:
            return
        if self.critic.last.misfit > c.max_fit_residual:
            self._note(PolicyEvent.REJECTED, f'critic: {_misfit(self.critic.last)} > '
                                             f'{c.max_fit_residual:g}')
            return
        if c.rollout_test and self.observer is not None and self.observer.model is None:
            # nothing to fly a proposal through: the robot has not moved enough to identify
            # its motion (a base friction holds), and a critic fitted to a robot that stands
            # still says nothing of its velocity feedback (at mu = 0.3 it proposed
            # anti-damping gains of +200 N s/m, adopted, that later threw the robot)
            self._note(PolicyEvent.REJECTED, 'no identified model of the motion yet')
            return
        Wa, Wd = self._target
        tau0, x0, *_ = window.samples()
        u_applied = window.applied()
        # only where the data are: below the times-to-go the samples cover, the greedy
        # gain is held at its value at their edge (guard.held_below)
        tau_low = float(np.quantile(tau0, c.coverage_quantile))
        held = partial(held_below, self.time_basis.batch, tau_low=tau_low, horizon=c.horizon)
        greedy_a = held(-self._greedy('u').T)
        greedy_d = held(self.gamma ** -2 * self._greedy('d').T) if self.robust else Wd
        greedy_a = self._held_where_away(greedy_a, tau_low)
        Z = (self.time_basis.batch(tau0)[:, :, None] * x0[:, None, :]).reshape(len(x0), -1)
        # the floor of the trust region: the probing scale or the forces applied so far,
        # over the size of the states they were applied in (N per state unit)
        force = self._force_scale(u_applied)
        scale = float(np.sqrt(np.mean(np.sum(x0 ** 2, axis=1))))
        taus = np.linspace(0.0, c.horizon, 6)
        change = np.array([np.linalg.norm(self.gain(t, greedy_a) - self.gain(t, Wa)) for t in taus])
        current = np.array([np.linalg.norm(self.gain(t, Wa)) for t in taus])
        s = trust_step(change, current, force / max(scale, 1e-9), c.trust_growth)
        du = float(np.abs(Z @ (greedy_a - Wa)).max(initial=0.0))
        allowed = max(c.value_tolerance, self._negative_value_share(self.critic.theta, Wa, Wd,
                                                                    self.critic.last))
        if du * s > c.force_limit:    # never a change beyond the actuator's range on the data
            s = c.force_limit / du
        why = ''
        for _ in range(4):
            cand = (Wa + s * (greedy_a - Wa), Wd + s * (greedy_d - Wd))
            proposal = fit(partial(self._rows, policy=cand), window, self.critic.theta, c.ridge)
            theta = proposal.theta
            share = self._negative_value_share(theta, *cand, proposal)
            if proposal.misfit > c.max_fit_residual:
                why = f'{_misfit(proposal)} > {c.max_fit_residual:g}'
            elif share > allowed:
                why = f'negative value share {share:.3g} > {allowed:.3g}'
            elif (self._completed is not None and self._full_legs < c.widen_after_legs
                  and not self._definite_value(proposal, *cand)):
                why = 'value kernel not positive definite on [T/2, T]'
            elif (away := self._carries_away(cand[0])) is not None:
                why = str(away)
            else:
                self._target = (cand[0].copy(), cand[1].copy())
                self._adopted_since = True
                self._note(PolicyEvent.ADOPTED, f'step {s:.3g} of the greedy change')
                return
            s *= 0.5
        self._note(PolicyEvent.REJECTED, f'proposal (step {2 * s:.3g}): {why}')

    def _held_where_away(self, W: Array, tau_low: float) -> Array:
        """The critic's greedy gain, held where flown through the model it carries a robot away.

        Where its rollout from rest (:meth:`rollout.Rollout.away`) ends farther from the target
        than standing still by more than ρ, the gain below the start of that rollout is held
        at its value there (:func:`guard.held_below`: the gain of a longer horizon), up to three
        times; as the coverage hold does where the data say nothing, here where the critic's
        low times to go are biased (odometry noise and a delay). W unchanged without a model.
        """
        rollout = self._rollout()
        if rollout is None:
            return W
        for _ in range(3):
            away = rollout.away(partial(self.gain, Wa=W))
            if away.excess <= self.config.rho or away.start <= tau_low:
                break
            tau_low = away.start
            W = held_below(self.time_basis.batch, W, tau_low, self.config.horizon)
        return W

    def _carries_away(self, Wa: Array) -> AwayFrom | None:
        """Where a proposal carries a robot at rest away, beyond what the guard tolerates.

        Through the observer's identified model (:class:`rollout.Rollout`), from eight
        times to go over the horizon: its relative excess over standing still may be at most
        what the divergence watch lets run (``divergence_distance`` - 1), or the current
        target's own if that is more (an escalation is stopped where it
        starts). None when it passes, without a model, or with ``rollout_test`` off.
        """
        rollout = self._rollout()
        if rollout is None:
            return None
        ours = rollout.away(partial(self.gain, Wa=Wa))
        if (ours.excess <= self.config.divergence_distance - 1.0
                or ours.excess <= rollout.away(partial(self.gain, Wa=self._target[0])).excess):
            return None
        return ours

    def _rollout(self) -> Rollout | None:
        """The rollouts of the observer's current model, built once per model.

        None without a model or with ``rollout_test`` off.
        """
        c = self.config
        if not c.rollout_test or self.observer is None or self.observer.model is None:
            return None
        model = self.observer.model
        if self._rollout_of is None or self._rollout_of.model is not model:
            self._rollout_of = Rollout(model, c.horizon, c.dt, np.linspace(c.horizon, c.dt, 8))
        return self._rollout_of

    def _force_scale(self, u_applied: Array) -> float:
        """N: the probing scale, or the RMS force applied in the stored data if larger.

        The force the robot has already been pushed with: the trust region's floor and
        the brake's first force.
        """
        pushed = float(np.sqrt(np.mean(u_applied ** 2))) if len(u_applied) else 0.0
        return max(2.0 * self.config.probing_std, pushed)

    def _definite_value(self, proposal: Fit, Wa: Array, Wd: Array) -> bool:
        """Whether a policy's value kernel under a critic fit is positive definite on [T/2, T].

        Not confidently indefinite: the least eigenvalue λ = vᵀP̂v (v its eigenvector) is
        linear in θ, and λ + z σ_λ > 0 is asked, σ_λ its standard error under the fit's
        spread and z the one-sided normal quantile of :data:`guard.FALSE_ALARM`: a proposal
        whose value is definite is rejected by noise with probability at most α. Where the
        data identify a direction poorly σ_λ is large and this passes more than λ > 0 did:
        on the heavy rover (120 kg, 8 kg/s), offline, 10 of 16 missions ended within 5 % of
        the Riccati policy against 13 with λ > 0 and 12 with λ - z σ_λ > 0 (shown definite);
        under odometry noise, a delay and a sinusoid both of those held the learner back
        (last ten 1.15-1.44 against 1.01-1.04), and this is kept.
        """
        z = float(norm.ppf(1.0 - FALSE_ALARM))
        for tau in np.linspace(0.5 * self.config.horizon, self.config.horizon, 6):
            values, vectors = np.linalg.eigh(self.policy_value_kernel(tau, proposal.theta, Wa, Wd))
            U = self.policy_actions(tau, vectors[:, 0], Wa, Wd)
            g = 2.0 * (self.time_basis(tau)[:, None] * (U[self.basis.rows] * U[self.basis.cols])
                       [None, self.basis.free]).ravel()
            if values[0] + z * float(proposal.standard_errors(g[None])[0]) <= 0.0:
                return False
        return True

    def revert(self, reason: str, t: float = 0.0, brake: bool = False) -> None:
        """A leg diverged: back to the last policy that completed a leg (or the initial one).

        When nothing was adopted since that policy completed its leg, it is the policy
        that diverged (in a direction its completed legs never went), and the hold is
        the initial policy instead. The actors and their target both jump there and stay
        for the rest of the leg; the data of the diverged leg stay in the critic's
        window (they are valid rows for any policy). A hold to the initial policy brakes
        instead with ``safe_hold: brake`` (the default; :class:`guard.Brake`, starting
        from the probing scale or the RMS force of the stored data): the robot is stopped
        where it is, and the initial policy takes over again at the next leg. ``brake``
        (a leg that left its line, :class:`guard.DivergenceWatch`) brakes in either case and
        keeps the completed policy once: a turn sharper than any before leaves the line
        under a good policy too. A second such brake under it, with no leg completed in
        between, discards it: seen on the heavy rover, a policy that had completed a leg
        along y had a negative gain along x, and kept through brake after brake it drove
        the robot 1 km off the map at the force limit.
        A brake lasts until the robot is at rest, at most a horizon from ``t`` (s).
        """
        if self._completed is not None and not self._adopted_since:
            if brake and not self._spared:
                self._spared = True      # off its line: the robot may have turned too fast
            else:
                self._completed = None   # it is the policy that diverged
        event = PolicyEvent.REVERTED if self._completed is not None else PolicyEvent.HOLD
        Wa, Wd = self._completed if self._completed is not None else self._initial
        self._Wa, self._Wd = Wa.copy(), Wd.copy()
        self._target = (Wa.copy(), Wd.copy())
        self._held = True
        self._adopted_since = False      # the actors now run the policy reverted to
        if brake or (event is PolicyEvent.HOLD and self.config.safe_hold is SafeHold.BRAKE):
            self._braking = True
            self._brake_started, self._brake_until = t, t + self.config.horizon
            self._brake.start(max(self._force_scale(self.critic.window.applied()), 1.0))
            reason += ', braking'
        self._note(event, 'leg diverged: ' + reason)

    def _note(self, event: PolicyEvent, reason: str) -> None:
        self._events.append((event, reason))
        self.event_counts[event] += 1

    def _rows(self, *batch: Array, policy: tuple[Array, Array] | None = None
              ) -> tuple[Array, Array, Array, Array]:
        """Bellman rows of the batch for ``policy`` (Wa, Wd); by default the actors' own."""
        c = self.config
        Wa, Wd = (self._Wa, self._Wd) if policy is None else policy
        pol = Policy(Wa, Wd, c.M, c.R, c.P_T, self.gamma, self.time_basis)
        return bellman_rows(self.basis, pol, self._fixed_w, c.dt, *batch)
