"""Model-free finite-horizon continuous-time Q-learning (RRT-QX §4; robust: ACC 2019 §III-IV).

The controller never sees the plant matrices. Per control period Δt it receives the state
x̄ relative to the leg target and the time t, and answers the force u. Sign convention:
û = Ŵaᵀ μ(τ) x̄ = -K̂(τ) x̄, so :meth:`QLearningController.gain` is comparable with the
Riccati gain R⁻¹BᵀP(τ); the disturbance actor is d̂ = Ŵdᵀ ξ(τ) x̄ = L̂(τ) x̄, comparable
with γ⁻²FᵀP(τ). Here μ(τ) = ξ(τ) = φ(τ) ⊗ I_n with the time basis φ of :mod:`basis`.

Per step (RRT-QX Algorithm 1, lines 12-16): the critic errors e_c1, e_c2 of the last Δt
(:mod:`bellman`, which also documents how the integrals are evaluated from the samples and
the probing-noise correction), the critic law (:mod:`critic`), the actor steps, then the
control with probing noise, saturated to the actuator's limit. Safeguards, all
model-free: Q̂_uu = R, Q̂_ud = 0, Q̂_dd = -γ²I are fixed (the cost's own weights); actor
steps are normalised; the first leg only collects data. Beyond the papers (:mod:`guard`):
the actors follow a *target* that changes only when the critic's proposal passes the
checks of :meth:`QLearningController.policy_improvement` (a trust region, the fit, a
positive-definite value of the proposed policy), and a leg that diverges reverts them to
the last policy that completed a leg.

This module holds the controller's state, its legs, its step and its actors; the critic's
updates and the guarded policy iteration are :mod:`policy_iteration`'s, the readouts of
the weights (gains, kernels) :mod:`readout`'s.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from scipy.stats import chi2
from numpy.typing import NDArray

from .basis import QuadraticBasis, TimeBasis
from .config import ActorLaw, ControllerConfig, PushLaw, StepInfo, Variant
from .critic import LeastSquaresCritic, make_critic
from .guard import FALSE_ALARM, Brake, DivergenceWatch, KeepOff, PolicyEvent, Sensing, face_ahead
from .observer import Observer, PushCanceller
from .held_short import HeldShort
from .push_feedforward import PushFeedforward
from .policy_iteration import PolicyIteration
from .probing import Probing
from .rollout import fly, spread
from .readout import _features
from .stability import gain_warnings

Array = NDArray[np.float64]


def _overcome(held: Array, friction: Array) -> Array:
    """N: the integral force and the friction compensation together, friction counted once.

    Both overcome the same friction where they point the same way: integral action grew
    until the robot moved, the compensation adds the identified level. Summed, a robot the
    integral force had set free got the friction twice (MuJoCo μ = 0.3, seed 15: 381 N
    along an axis with 118 N of friction, 5.9 m/s). Per axis the larger of the two where
    they agree in sign, their sum where they do not.
    """
    same = np.sign(held) == np.sign(friction)
    larger = np.where(np.abs(held) >= np.abs(friction), held, friction)
    return np.asarray(np.where(same, larger, held + friction), dtype=float)


def _pad(W: Array, rows: int) -> Array:
    return np.vstack([W, np.zeros((rows, W.shape[1]))])


class QLearningController(PolicyIteration):
    """Actor/critic Q-learning controller for one robot; weights carry from leg to leg.

    Parameters
    ----------
    config
        Controller parameters; scalar matrices are expanded to n x n / m x m.
    n, m, q
        State, control and disturbance dimensions (the nominal variant takes the q
        measured components into its critic's rows when ``measured_disturbance``).
    rng
        Source of the probing noise.
    """

    def __init__(self, config: ControllerConfig, n: int, m: int, q: int,
                 rng: np.random.Generator) -> None:
        self.config = config.expanded(n, m)
        self.robust = self.config.variant is Variant.ROBUST
        self.gains = self.config.gains
        self.gamma = self.config.gamma if self.robust and self.config.gamma is not None else 0.0
        """Attenuation level γ of the game (0 in the nominal variant: d, measured or not, is no
        input it chooses and carries no cost)."""
        # the nominal variant's measured disturbance enters the critic's rows with d̂ = 0
        # robust on the observer's estimate: the game is against the matched push, per input
        estimated = self.robust and self.config.disturbance_estimate
        self.n, self.m = n, m
        self.q = m if estimated else (q if self.config.reads_disturbance else 0)
        self.time_basis = TimeBasis(self.config.time_rates, self.config.time_powers, self.config.horizon)
        self.basis = QuadraticBasis(n, m, self.q)
        L, b = self.time_basis.size, self.basis
        self._fixed_w = b.fixed_weights(self.config.R, self.gamma)
        self._free_xu = np.searchsorted(b.free, b.xu)
        self._free_xd = np.searchsorted(b.free, b.xd)
        self.critic = make_critic(np.zeros(L * b.free.size), self.config, n, m, self.q)
        self._Wa = np.zeros((L * n, m))
        if self.config.initial_gain is not None:
            self._Wa[:n] = -np.asarray(self.config.initial_gain, dtype=float).reshape(m, n).T
        self._Wd = np.zeros((L * n, self.q))
        self._Rinv = np.linalg.inv(self.config.R)
        c = self.config
        self._target = (self._Wa.copy(), self._Wd.copy())
        """The actors' target (control, disturbance): changed only by an adoption or a revert."""
        self._initial = (self._Wa.copy(), self._Wd.copy())
        self._completed: tuple[Array, Array] | None = None
        self._adopted_since = False
        self._spared = False
        """Whether the completed policy has already been kept through a line-watch brake
        it was blamed for (it is not a second time, until a leg completes)."""
        """Whether a target was adopted since a leg last completed."""
        """The actors' weights when a leg last entered its window (the revert point)."""
        self._watch = DivergenceWatch(c.divergence_distance, c.divergence_floor,
                                      c.divergence_speed, c.horizon,
                                      deviation=c.divergence_deviation, stop_time=c.hold_stop_time,
                                      steps=max(int(round(c.horizon / c.dt)), 1))
        self._held = False
        self.sensing = Sensing()
        """Odometry noise and actuation delay the keep-offs allow for: no delay until the
        observer has identified one (a push toward safety is not held back on a guess)."""
        self._braking_sense = Sensing(dead_steps=c.observer_lags if c.observes else 0)
        """The brake's: until the observer has identified the delay, the longest it can
        identify (a brake that doubles every step against a delayed actuator reaches the
        limit before its first force has acted: 1000 N on a 40 kg rover, 0.1 s late)."""
        self._brake = Brake(c.force_limit, c.hold_stop_time, c.dt, sensing=self._braking_sense)
        self._keep_off = KeepOff(c.keep_off, c.force_limit, c.dt, lead=c.hold_stop_time,
                                 sensing=self.sensing)
        self._keep_ahead = KeepOff(c.keep_off, c.force_limit, c.dt, lead=c.hold_stop_time,
                                   sensing=self.sensing)
        """The keep-off of the obstacle ahead along the velocity (:func:`guard.face_ahead`)."""
        self._held_short = HeldShort(m, c.rho, c.horizon, c.dt,
                                     c.force_limit if c.integral_action else math.inf,
                                     sensing=self.sensing)
        """Integral action on a leg retried toward the waypoint the last one ran out on."""
        self._kept_in_leg = False
        """Whether a keep-off pushed in this leg (its running out arms integral action only
        where the model's rollout tells, :meth:`_off_own_policy`)."""
        self._braked_in_leg = False
        """Whether the brake acted in this leg (its running out arms no integral action)."""
        self._leg_x0: Array | None = None
        """x̄0 of the current leg (or horizon), for :meth:`_off_own_policy`."""
        self._leg_gains: list[Array] = []
        """The actor's gain K̂(τ) at each step of the current leg so far (its policy as it
        flew the leg: the actor moves toward each adopted target within a leg)."""
        self._leg_open: list[Array] = []
        """N: what each of those steps applied beyond the policy's feedback -K̂ x̄ (probing,
        a feed-forward, integral action, friction compensation, a keep-off, saturation)."""
        self._leg_last: deque[Array] = deque()
        """The velocities of the current leg's last steps so far (at most the readings
        whose mean tells rest under the odometry's noise, :meth:`guard.Sensing.samples_for`)."""
        self._braking = False
        """Whether the robot is being braked (a HOLD with ``safe_hold: brake``, or a leg that
        left its line): until the robot is at rest, at most T, and then only on a policy
        that completed a leg or from a new leg on (the initial policy may be the zero gain,
        under which a lightly damped robot drifts off again)."""
        self._brake_started = self._brake_until = 0.0
        self._events: list[tuple[PolicyEvent, str]] = []
        self.event_counts = {e: 0 for e in PolicyEvent}
        """How often each :class:`guard.PolicyEvent` happened."""
        self.leg_index = -1
        self._t0 = 0.0
        self._prev: tuple[float, Array, Array] | None = None
        self.observer = (Observer(n, m, c.observer_lags, c.observer_memory, c.observer_ar,
                                  reads_pushes=c.cancels_push,
                                  velocity=slice(m, 2 * m) if n == 2 * m else None)
                         if c.observes else None)
        """The one-step model the critic learns through (:mod:`observer`); None: the rows take
        the odometry and the commanded force as they are."""
        self._identifier = (Observer(n, m, c.observer_lags, c.observer_memory, c.observer_ar,
                                     velocity=slice(m, 2 * m) if n == 2 * m else None)
                            if self.observer is None and c.integral_action else None)
        """Without :attr:`observer` (a measured disturbance), the same identification for
        integral action's arming alone (:meth:`_off_own_policy`); the critic does not see it."""
        law = c.push_feedforward_law
        self._canceller = (PushCanceller(m, c.dt, c.push_filter_time, FALSE_ALARM)
                           if c.cancels_push and law is PushLaw.CANCEL else None)
        """The cancelling push feed-forward (``push_feedforward_law: cancel``); None: not it."""
        self._forward = (PushFeedforward(m, c.dt, c.M, c.R, FALSE_ALARM)
                         if c.cancels_push and law is PushLaw.OPTIMAL else None)
        """The LQ-optimal push feed-forward (``push_feedforward_law: optimal``); None: not it."""
        self._rollout_of = None
        """The guard's rollouts of the observer's current model (:mod:`rollout`), built once
        per model."""
        self._segment = 0
        """Changes with the leg coordinates (a new leg or horizon): the observer's segments."""
        self._prev_t = 0.0
        """s: the time of the step in :attr:`_prev`."""
        self._step_id = -1
        """The observer's id of the step in :attr:`_prev`."""
        self._steady = np.zeros(m)
        """N per input: the steady push the observer last found (zero where noise could have
        made it), which the keep-offs cancel near an obstacle."""
        self._since_eval = 0
        self.critic_trusted = False
        """Whether the critic's value of the actors' policy is positive (a diagnostic)."""
        self._full_legs = 0
        self.widened = False
        """Whether the time basis was widened by ``widen_powers`` (see :meth:`widen_time_basis`)."""
        self._d_out = np.zeros(self.q)
        tc = self.config.probing_correlation
        self._probing_u = Probing(m, self.config.dt, tc, self.config.probing_across, rng,
                                  self.config.probing_line_fraction)
        self._probing_d = Probing(self.q, self.config.dt, tc, 1.0, rng)
        self._noise_d = np.zeros(self.q)
        self.info = StepInfo()
        self.warnings: list[str] = gain_warnings(self)

    # ----------------------------------------------------------------- legs
    def start_leg(self, x0_bar: Array, t: float, completed: bool | None = None,
                  moved: Array | None = None) -> None:
        """Begin a new finite-horizon problem at time t (s) from x̄0 (RRT-QX Alg. 1, l. 6).

        The learned weights are kept: the Q-function depends on x̄, u and τ only.
        ``completed`` says whether the previous leg ended in its window D <= ρ D0 (then
        its policy becomes the one a diverging leg reverts to); None infers it from the
        leg's duration (it ended before its horizon), which is right where legs end only
        at their window or horizon. ``moved``: how far the target moved from the previous
        leg's, x_r(new) - x_r(old) (state units), when the caller knows (the divergence
        watch measures from the reference leg's target, :class:`guard.DivergenceWatch`).
        """
        renew = True   # a fresh divergence reference: first leg, completed leg, a revert
        armed = False  # the last leg ran its horizon short of its window, held there
        if self.leg_index >= 0:
            ran_out = t - self._t0 >= self.config.horizon - 0.5 * self.config.dt
            # a leg the brake acted on was held by the safety shell, not short: it arms
            # nothing. Otherwise a leg that ran out was held where its robot ended elsewhere
            # than its own policy would have taken it (the policy may be slow; the keep-offs'
            # forces are in the rollout, and a leg they acted on arms nothing without a
            # model: :meth:`_off_own_policy`) and, before any policy completed a leg, at rest:
            # the initial policy's probing walks a robot about, and friction or a push holds
            # it still (integral action armed on a probing walk would take over from a
            # learner that has not started). The model's rollout last: it is the dearest
            armed = (ran_out and not self._braking and not self._braked_in_leg
                     and (self._completed is not None or self._at_rest_at_last_leg_end())
                     and self._off_own_policy(unknown=not self._kept_in_leg))
            entered = not ran_out if completed is None else completed
            if entered:
                self.completed_leg()
            else:
                renew = self._held
            # a leg that a new plan cut short says nothing of the policy: the streak of
            # legs that ran their horizon goes on through it, and ends at a window
            if ran_out:
                self._full_legs += 1
            elif entered:
                self._full_legs = 0
            c = self.config
            if (self._full_legs >= c.widen_after_legs and c.widen_powers and not self.widened
                    and isinstance(self.critic, LeastSquaresCritic)):
                self.widen_time_basis()
            self._held = False   # the leg that reverted is over: its data may propose
            self.policy_evaluation()
        self.leg_index += 1
        self._t0 = float(t)
        self._prev = None
        self._segment += 1
        self._watch.start(np.asarray(x0_bar, dtype=float), renew,
                          None if moved is None else np.asarray(moved, dtype=float))
        self._held = False   # a brake goes on (:meth:`step`)
        self._probing_u.start_leg(np.asarray(x0_bar, dtype=float))
        self._kept_in_leg = self._braked_in_leg = False
        self._leg_last.clear()
        self._record_leg_from(x0_bar)
        self._held_short.start_leg(np.asarray(x0_bar, dtype=float), armed)
        if armed and self._held_short.active:
            self._note(PolicyEvent.HELD_SHORT,
                       'the last leg ran its horizon short of its window: integral action')

    def _record_leg_from(self, x0_bar: Array) -> None:
        """Start recording a leg (or horizon) from x̄0 for :meth:`_off_own_policy`."""
        self._leg_x0 = np.array(x0_bar, dtype=float)
        self._leg_gains.clear()
        self._leg_open.clear()

    def _off_own_policy(self, unknown: bool = True) -> bool:
        """Whether the leg that ran out ended elsewhere than its own policy would have taken it.

        ``unknown``: the answer where there is nothing to tell by (no model, no record).

        Its start x̄0 flown through the observer's identified model (:func:`rollout.fly`: no
        push, no friction, no noise) by the actor's gain K̂(τ) at each of its steps, with all
        the leg added to that feedback (probing, feed-forward, the integral force itself: a
        force armed and left out would set the two apart and arm it again and again),
        clipped at the limit, to the leg's last step, against where the robot was then:
        held, when the two states lie farther apart than the window ρ D0 (in x̄, as the
        window counts D: a difference the leg would accept is not a hold) and than the
        steps' unexplained part (the model's residual covariance, as white noise, through
        the same closed loop: :func:`rollout.spread`) and the odometry's noise explain, at
        :data:`guard.FALSE_ALARM` (1 %, χ² on the squared Mahalanobis distance).

        A policy slower than its window asks (the finite-horizon optimum of a plant whose
        force is dear, R large, or that is heavy and lightly damped ends its horizon short
        of its window) ends where the model says it does, and nothing held it; a push or
        friction holds the robot where the model has it moving on. Either way round: a
        model fitted to the noise of a robot friction held still (the zero gain's 20 N of
        probing against 39 N) has it drift off anywhere, and the robot stayed. On a light,
        lightly damped plant with a slow policy a white push walks the robot farther than
        the window over a horizon: without the noise test integral action armed there
        (seven times on ``controller_robustness``'s plant 37) and drove it on. ``unknown``
        without a model (nothing to tell them apart by). Without the critic's observer (a measured
        disturbance) the model is :attr:`_identifier`'s.
        """
        observer = self.observer
        if observer is None and self._identifier is not None:
            observer = self._identifier
            observer.update()
        if observer is None or observer.model is None or self._prev is None:
            return unknown
        c = self.config
        steps = int(round((self._prev_t - self._t0) / c.dt))
        if steps < 1 or self._leg_x0 is None or len(self._leg_gains) < steps:
            return unknown
        gains = np.array(self._leg_gains[:steps])
        path = fly(observer.model, gains, self._leg_x0, np.array(self._leg_open[:steps]),
                   c.force_limit)
        apart = self._prev[1] - path[-1]
        if not np.all(np.isfinite(apart)):
            return unknown
        if float(np.linalg.norm(apart)) <= c.rho * float(np.linalg.norm(self._leg_x0)):
            return False
        # beyond what the unexplained part of each step and the odometry's noise make of it
        cov = spread(observer.model, gains) + np.diag(observer.variance)
        distance = float(apart @ np.linalg.pinv(cov) @ apart)
        return not distance <= float(chi2.ppf(1.0 - FALSE_ALARM, apart.size))

    def _at_rest_at_last_leg_end(self) -> bool:
        """Whether the robot ended the last leg at rest.

        The mean velocity of its last readings at most the brake's rest speed or, under
        odometry noise, what the mean of that many readings of a robot at rest shows with
        probability :data:`FALSE_ALARM` (:meth:`guard.Sensing.rest`). One reading with exact
        odometry; under noise as many as bring that quantile down to the rest speed
        (:meth:`guard.Sensing.samples_for`: 10 at σ_v = 0.05 m/s): one reading of a robot
        moving at 0.19 m/s falls below the quantile of one (0.15 m/s) on about one step in
        five, and so armed integral action at the end of its legs.
        """
        if not self._leg_last:
            return True
        mean = np.mean(np.asarray(self._leg_last), axis=0)
        rest = self.sensing.rest(self._brake.rest_speed, len(self._leg_last))
        return float(np.linalg.norm(mean)) <= rest

    def renew_horizon(self, x0_bar: Array, t: float) -> None:
        """Keep station on a reached target with a fresh horizon from time t (s).

        The same leg goes on as a new finite-horizon problem from x̄0 (receding horizon):
        τ restarts at T, the divergence watch takes x̄0 as its reference, a hold ends;
        no leg is counted (no policy evaluation, no probing decay, no widening of the time basis).
        """
        self._t0 = float(t)
        self._prev = None
        self._record_leg_from(x0_bar)
        self._segment += 1
        self._watch.start(np.asarray(x0_bar, dtype=float))
        self._probing_u.follow_line(np.asarray(x0_bar, dtype=float))
        self._held = False

    def set_odometry_variance(self, variance: Array) -> None:
        """The variance of each state's measurement (the odometry's covariance diagonal).

        The observer smooths the states it learns from with it, and the brake and the
        keep-offs allow for the velocity's (:class:`guard.Sensing`); zero: exact odometry.
        """
        variance = np.asarray(variance, dtype=float)
        for observer in (self.observer, self._identifier):
            if observer is not None:
                observer.variance = variance.copy()
        velocity = variance[2:2 + self.m]
        std = float(np.sqrt(velocity.mean())) if velocity.size else 0.0
        self.sensing.velocity_std = self._braking_sense.velocity_std = std
        self._watch.position_std = float(np.sqrt(variance[:2].mean()))

    def completed_leg(self) -> None:
        """Mark the current leg as completed (it entered its window).

        Its policy becomes the one a diverging leg reverts to.
        """
        self._completed = (self._Wa.copy(), self._Wd.copy())
        self._adopted_since = self._spared = False

    @property
    def _kept_off_from(self) -> list[Array]:
        """The unit normals (obstacle to robot) the keep-offs pushed along on the last step.

        Empty where none pushed; integral action grows by no part toward those obstacles.
        """
        return [k.normal for k in (self._keep_off, self._keep_ahead) if k.normal is not None]

    def time_to_go(self, t: float) -> float:
        """τ = T - (t - t_leg), s, clipped at 0."""
        return max(self.config.horizon - (t - self._t0), 0.0)

    @property
    def probing_std(self) -> float:
        """Current control probing standard deviation, N (decays per leg)."""
        c = self.config
        return max(c.probing_std * c.probing_decay ** max(self.leg_index, 0), c.probing_floor)

    # ---------------------------------------------------------------- step
    def step(self, t: float, x_bar: Array, d_applied: Array | None = None,
             nearest: tuple[float, Array] | None = None,
             ahead: tuple[float, Array] | None = None) -> Array:
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
        nearest
            The nearest detected obstacle: its distance from the robot (m) and the unit
            vector from it to the robot, for the keep-off (:class:`guard.KeepOff`); None:
            not known.
        ahead
            The detected obstacle ahead along the velocity: how far the robot's disc travels
            before it meets it (m) and the unit normal of its boundary there, toward the
            robot, for the second keep-off (:func:`guard.face_ahead`); None: not known.

        Returns
        -------
        numpy.ndarray
            The force u to hold over [t, t + Δt): actor output plus probing noise,
            saturated to ±``force_limit``.
        """
        if self.leg_index < 0:
            self.start_leg(x_bar, t)
        x = np.array(x_bar, dtype=float)  # a copy: it is kept for the next step
        tau = self.time_to_go(t)
        e_c1 = e_c2 = 0.0
        feed = self._canceller if self._canceller is not None else self._forward
        if (self._prev is not None and feed is not None and self.observer is not None
                and abs(t - self._prev_t - self.config.dt) < 0.5 * self.config.dt):
            # the step that just ended, if it was one Δt (a free-running robot side can skip
            # ticks, and over a gap the model's one step does not hold)
            feed.update(self.observer.last_push(x))
        if self._prev is not None:
            measured = d_applied is not None and self.q > 0 and self.config.reads_disturbance
            d_prev = np.asarray(d_applied, dtype=float) if measured else self._d_out
            e_c1, e_c2 = self.critic_update(tau, x, d_prev)
        reason = self._watch.check(x)
        if reason:
            self.revert(reason, t, brake=self._watch.off_line)
            self._held_short.drop()
        phi = self.time_basis(tau)  # after the update, which may widen the basis
        e_a = e_d = np.zeros(0)
        if self.leg_index >= self.config.actor_warmup_legs:
            e_a = self.actor_update(phi, x, self._target[0])
            if self.robust:
                e_d = self.disturbance_actor_update(phi, x, self._target[1])
        noise = self._probing_u.sample(self.probing_std, x[:2])
        limit = self.config.force_limit
        if self._braking and (t >= self._brake_until or self._brake.at_rest and (
                self._completed is not None or self._t0 > self._brake_started)):
            self._braking = False   # at rest: a policy that completed a leg, or a new leg
            self._watch.start(x)    # watched afresh from where it stopped (it trips once a leg)
        feedforward = np.zeros(self.m)
        if self._canceller is not None and self.observer is not None:
            feedforward = self._canceller.force(self.observer.push_noise(self._canceller.a))
        elif self._forward is not None:
            feedforward = self._forward.force()
        # ∂u/∂x̄ of this step's force, for the observer: the actor's -K̂(τ) (the brake, the
        # keep-offs and integral action left out), none along a saturated axis
        sensitivity = np.zeros((self.m, x.size))
        feedback = np.zeros(self.m)
        if self._braking:
            noise = np.zeros(self.m)
            self._held_short.drop()
            u = np.clip(self._brake(x, self.m), -limit, limit)
        else:
            sensitivity = self._policy_sensitivity(phi)
            feedback = self._policy_u(phi, x)
            u = feedback + noise + feedforward
            held = self._held_short(x, blocked=self._kept_off_from, time_left=tau)
            friction = self._friction_force(u + held, x)
            u = np.clip(u + _overcome(held, friction), -limit, limit)
        velocity = x[2:2 + self.m]
        obstacles = (nearest, None if ahead is None else face_ahead(*ahead, velocity))
        for keep, obstacle in zip((self._keep_off, self._keep_ahead), obstacles, strict=True):
            if obstacle is not None and x.size >= 2 + self.m:   # it acts within its reach only
                u = np.clip(keep(u, velocity, obstacle[0], obstacle[1],
                                 lambda: self._force_scale(self.critic.window.applied()),
                                 self._steady + feedforward), -limit, limit)
            else:
                keep.release()
        if not self._braking:   # what the leg applied beyond its policy's feedback
            self._leg_gains.append(-sensitivity)
            self._leg_open.append(u - feedback)
        self._kept_in_leg = self._kept_in_leg or bool(self._kept_off_from)
        self._braked_in_leg = self._braked_in_leg or self._braking
        self._leg_last.append(x[self.m:2 * self.m].copy())
        while len(self._leg_last) > self.sensing.samples_for(self._brake.rest_speed):
            self._leg_last.popleft()
        if self.robust:
            d_std = self.config.disturbance_probing_std * self.config.probing_decay ** self.leg_index
            self._noise_d = self._probing_d.sample(d_std)
            self._d_out = self._policy_d(phi, x) + self._noise_d
        self._prev = (tau, x, u)  # the applied force: the rows stay right when u saturates
        self._prev_t = float(t)
        sensitivity[np.abs(u) >= limit] = 0.0
        if self.observer is not None:
            # with the feed-forward, the model is not identified from a braked step. The brake
            # holds the robot against the push, a force that cancels the push step by step (a
            # collinearity no regression can split) at a position that hardly moves, and the
            # model fitted across a hold took a spring the rover has not (256 N/m), through
            # which it read a 580 N push at rest; the rows still learn from the step
            fits = not (self._braking and self.config.cancels_push)
            self._step_id = self.observer.record(x, u, self._segment, fits, sensitivity)
        elif self._identifier is not None:
            self._identifier.record(x, u, self._segment, True, sensitivity)
        events, self._events = self._events, []
        self.info = StepInfo(tau=tau, e_c1=e_c1, e_c2=e_c2, e_a=e_a, e_d=e_d, probing=noise,
                             keep_off=self._keep_off.push + self._keep_ahead.push,
                             policy_event=';'.join(e.value for e, _ in events),
                             policy_reason='; '.join(r for _, r in events))
        return u

    def _friction_force(self, u: Array, x: Array) -> Array:
        """N: Coulomb friction compensation, the identified level per axis (zero without one).

        Along each velocity component that moves, the friction level in its direction (the
        friction it meets while moving, cancelled); along one at rest (within the speed odometry
        noise makes, :meth:`observer.Observer.rest`), the level in the direction of the force
        ``u`` (what it takes to break free, so the force acts on the robot as it would without
        friction). So the robot moves as its linear part would, which is what the critic
        learns the Q-function of (the equivalent input carries the friction and this force,
        and nets them). Classic Coulomb compensation (e.g. Armstrong-Hélouvry, Dupont and
        Canudas de Wit 1994); the level is the observer's, identified from odometry and the
        forces (no model given). Not while braking: there the friction helps.
        """
        observer = self.observer
        if not self.config.friction_compensation or observer is None or observer.velocity is None:
            return np.zeros(self.m)
        level = observer.friction()
        if level is None:
            return np.zeros(self.m)
        v = x[observer.velocity]
        moving = np.abs(v) > observer.rest()
        return np.asarray(level * np.where(moving, np.sign(v), np.sign(u)), dtype=float)

    @property
    def d_hat(self) -> Array:
        """Disturbance actor output (with its probing noise) to apply over the next Δt."""
        return self._d_out.copy()

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
        extra = (len(powers) - len(c.time_powers)) * n
        self.time_basis = TimeBasis(c.time_rates, powers, c.horizon)
        # the old fit (of a value it could not represent) is no prior for the new one
        self.critic.theta = np.zeros(self.time_basis.size * b.free.size)
        self._Wa, self._Wd = _pad(self._Wa, extra), _pad(self._Wd, extra)
        self._target = (_pad(self._target[0], extra), _pad(self._target[1], extra))
        self._initial = (_pad(self._initial[0], extra), _pad(self._initial[1], extra))
        if self._completed is not None:
            self._completed = (_pad(self._completed[0], extra), _pad(self._completed[1], extra))
        self.widened = True

    def actor_update(self, phi: Array, x: Array, target: Array | None = None) -> Array:
        """Control-actor step towards ``target``, by default the critic's greedy policy (RRT-QX (23)).

        e_a = (Ŵa - Ŵa*)ᵀ z with z = μ(τ)x̄ = φ(τ) ⊗ x̄; for the greedy weights Ŵa* this is
        the papers' Ŵaᵀ z + Q̂_uu⁻¹ Q̂_ux(τ) x̄. GRADIENT: the normalised Euler step
        Ŵa ← Ŵa - α_a Δt z e_aᵀ / (1 + zᵀz); the plain step of (23) multiplies the error
        along z by 1 - α_a Δt ‖z‖², unstable once α_a Δt ‖x̄‖² > 2 (long legs), normalised
        the factor stays in (1 - α_a Δt, 1] whatever the state's size. WHITENED: see
        :class:`ActorLaw`. The controller passes the guard's adopted target.
        """
        target = -self._greedy('u').T if target is None else target
        e_a = (self._Wa - target).T @ _features(phi, x)
        self._Wa = self._actor_step(self._Wa, target, phi, x, e_a, self.gains.alpha_a)
        return e_a

    def disturbance_actor_update(self, phi: Array, x: Array, target: Array | None = None) -> Array:
        """Disturbance-actor step, ACC (23): e_d = (Ŵd - Ŵd*)ᵀ z.

        By default toward the critic's greedy Ŵd* (then e_d = Ŵdᵀ z + Q̂_dd⁻¹ Q̂_dx(τ) x̄,
        Q̂_dd = -γ² I).
        """
        target = self.gamma ** -2 * self._greedy('d').T if target is None else target
        e_d = (self._Wd - target).T @ _features(phi, x)
        self._Wd = self._actor_step(self._Wd, target, phi, x, e_d, self.gains.alpha_d)
        return e_d

    def _actor_step(self, W: Array, target: Array, phi: Array, x: Array, err: Array, alpha: float) -> Array:
        h = alpha * self.config.dt
        if self.config.actor_law is ActorLaw.WHITENED:
            return W - h * (W - target)
        z = _features(phi, x)
        return W - (h / (1.0 + z @ z)) * np.outer(z, err)

    def set_weights(self, critic: Array | None = None, actor: Array | None = None,
                    disturbance: Array | None = None) -> None:
        """Load learned weights (e.g. saved from a previous run); shapes as the accessors.

        Loaded actor weights are also the actors' target (an adopted policy).
        """
        L, b = self.time_basis.size, self.basis
        if critic is not None:
            self.critic.theta = np.asarray(critic, dtype=float).reshape(L, b.size)[:, b.free].ravel()
        if actor is not None:
            self._Wa = np.asarray(actor, dtype=float).reshape(self._Wa.shape).copy()
        if disturbance is not None:
            self._Wd = np.asarray(disturbance, dtype=float).reshape(self._Wd.shape).copy()
        self._target = (self._Wa.copy(), self._Wd.copy())

    def check_gains(self) -> list[str]:
        """Warnings where α_a, α_c, α_d violate the stability bounds for the current critic."""
        self.warnings = gain_warnings(self)
        return self.warnings

    # ------------------------------------------------------------- helpers
