"""Configuration of the Q-learning controller core (frozen, validated, with units).

:class:`ControllerConfig` is the one definition of the controller's settings: the
scenario's ``controller:`` section is read into it, the orchestrator hands it to the
controller node, the node declares its ROS parameters from it.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rrtq_common.run import STEP_S
from rrtq_common.settings import check, setting

class Variant(enum.StrEnum):
    """Which controller drives the robot (StrEnum: compares equal to its YAML string)."""

    NOMINAL = 'nominal'
    """Optimal control (RRT-QX §4): critic on U = (x̄, u)."""

    ROBUST = 'robust'
    """Two-player zero-sum game (ACC 2019 §III-IV): critic on U = (x̄, u, d)."""

    OPEN_LOOP = 'open_loop'
    """No learning: a scripted force profile (``forces``), for plant tests."""

    VF_LPC = 'vf_lpc'
    """VF-LPC: the receding-horizon actor-critic on an identified model with online
    sparse-GP compensation, tracking the guidance reference (``rrtq_controller.vf_lpc``)."""


class PushLaw(enum.StrEnum):
    """What the push feed-forward (``push_feedforward``) adds to the policy's force."""

    OPTIMAL = 'optimal'
    """The LQ-optimal feed-forward of the push the identified model predicts: its internal
    model (a constant and the harmonic the reads' periodogram shows) fitted over the memory
    and tracked by a Kalman filter, times the gain of the certainty-equivalent LQ problem
    (:mod:`rrtq_controller.push_feedforward`)."""

    CANCEL = 'cancel'
    """Minus the predicted push (α + β times the low-pass filtered reads,
    :class:`rrtq_controller.observer.PushCanceller`): the whole predictable push cancelled."""


class CriticLaw(enum.StrEnum):
    """How the critic weights are tuned from the integral Bellman equations."""

    GRADIENT = 'gradient'
    """The papers' normalised gradient descent, RRT-QX (22) / ACC (21), Euler-stepped."""

    LEAST_SQUARES = 'least_squares'
    """Recursive, exponentially weighted least squares over the same errors e_c1, e_c2."""


class SafeHold(enum.StrEnum):
    """What a leg holds when it diverged and no policy has completed a leg (the guard)."""

    BRAKE = 'brake'
    """A bounded force against the measured velocity, adapted on line (:class:`guard.Brake`)."""

    INITIAL = 'initial'
    """The initial policy (``initial_gain``; the zero gain when none is given)."""


class ActorLaw(enum.StrEnum):
    """How the actors follow the critic's greedy policy."""

    GRADIENT = 'gradient'
    """The papers' law RRT-QX (23) / ACC (22)-(23), a gradient of ½‖e_a‖² at the current x̄,
    Euler-stepped with normalisation: directions x̄ rarely visits (velocities) learn slowly."""

    WHITENED = 'whitened'
    """The same error averaged over isotropic x̄: Ŵ ← Ŵ - α Δt (Ŵ - Ŵ*), with Ŵ* the critic's
    greedy weights (-(R⁻¹Q̂_ux)ᵀ, γ⁻²Q̂_dxᵀ per time function); every direction alike."""


@dataclass(frozen=True)
class Gains:
    """The tuning gains in use, 1/s: the configured ones, or the controller's choice."""

    alpha_c: float = 90.0
    """Critic gain α_c (gradient law only)."""
    alpha_a: float = 1.2
    """Control-actor gain α_a (RRT-QX (23))."""
    alpha_d: float = 0.2
    """Disturbance-actor gain α_d (ACC (23)); robust variant only.

    ACC's 2.5 (and 1.2) let the simultaneous game iteration diverge in our trials.
    """


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


_POSITIVE: dict[str, Any] = {'low': 0.0, 'low_open': True}


@dataclass(frozen=True, kw_only=True)
class ControllerConfig:
    """Parameters of the finite-horizon Q-learning controller (and of the open-loop player).

    Matrices may be given as scalars (meaning scalar times identity); they are
    expanded by :meth:`expanded` once the dimensions n, m are known. A gain left out
    (None) is the controller's choice (:class:`Gains`).
    """

    variant: Variant = setting(Variant.NOMINAL, doc='nominal | robust | open_loop | vf_lpc')
    horizon: float = setting(10.0, unit='s', **_POSITIVE,
                             doc='T, the finite horizon of every leg (RRT-QX (2))')
    dt: float = setting(STEP_S, unit='s', **_POSITIVE, doc='Δt, the control period and '
                        'integral-reinforcement interval (RRT-QX (17))')
    M: Any = setting(10.0, rows='n', doc='state weight, n x n (or scalar), cost units per '
                     '(state unit)^2')
    R: Any = setting(0.02, rows='m', doc='control weight, m x m (or scalar), cost units per '
                     'N^2; also the fixed Q_uu')
    """The default is 0.02, not the paper's 2: on a rover without a spring, at R = 2 the
    finite-horizon optimum itself moves the robot 0.5 m of a 5 m leg in T = 10 s (force
    is dear), so no leg ever enters its window and a mission never reaches its goal; at
    0.02 the optimum enters the window of a 5 m leg in 5-8 s for masses of 10-120 kg. The
    paper's spring does the work where R = 2 (``scenarios/rrtqx_paper.yaml`` sets it)."""
    P_T: Any = setting(0.5, rows='n', doc='terminal Riccati matrix P(T), n x n (or scalar)')
    critic_law: CriticLaw = setting(CriticLaw.LEAST_SQUARES, doc='least_squares | gradient')
    actor_law: ActorLaw = setting(ActorLaw.WHITENED, doc='whitened | gradient')
    alpha_c: float | None = setting(None, unit='1/s', **_POSITIVE,
                                    doc='critic gain α_c (gradient law); None: Gains()')
    alpha_a: float | None = setting(None, unit='1/s', **_POSITIVE, doc='control-actor gain '
                                    'α_a (RRT-QX (23)); None: Gains()')
    alpha_d: float | None = setting(None, unit='1/s', **_POSITIVE, doc='disturbance-actor '
                                    'gain α_d (ACC (23)), robust variant; None: Gains()')
    actor_warmup_legs: int = setting(1, low=0, doc='legs during which the actors stay at '
                                     'their initial weights while the critic learns')
    gamma: float | None = setting(None, **_POSITIVE, doc='attenuation level γ, cost units per '
                                  'disturbance unit; required by the robust variant')
    rho: float = setting(0.15, low=0.0, low_open=True, high=1.0, high_open=True,
                         doc='admissible window ρ of the terminal-state evaluation '
                         'D <= ρ D0 (RRT-QX (4)-(5))')
    time_rates: tuple[float, ...] = setting((0.0, 0.5, 1.0, 2.0), unit='1/s', low=0.0,
                                            doc='decay rates λ_l of the time basis '
                                            'φ_l(τ) = exp(-λ_l τ); the first must be 0')
    """The first rate must be 0 (the constant function, which carries the fixed Q̂_uu = R)."""
    time_powers: tuple[int, ...] = setting((), low=1, doc='powers k of polynomial time '
                                           'functions (τ / T)^k appended to the exponentials')
    widen_powers: tuple[int, ...] = setting((1, 2), low=1, doc='powers k of (τ / T)^k the time '
                                            'basis is widened by, once, after '
                                            'widen_after_legs legs ran their whole horizon')
    """See :meth:`QLearningController.widen_time_basis`.

    The value of a policy that leaves the robot away from its target grows in τ (the zero
    policy on the rover without a spring: linearly), which no sum of decaying exponentials
    fits, so such a policy is never evaluated and nothing is learned from a zero gain. The
    powers are not used from the start: on the τ that legs visit they are nearly collinear
    with the exponentials and cost accuracy when the plant needs none (the paper's rover,
    small probing: gain error 0.47 instead of 0.08). Empty never widens.
    """
    widen_after_legs: int = setting(2, low=1, doc='legs in a row that end by running out of '
                                    'horizon after which the basis is widened')
    probing_std: float = setting(20.0, unit='N', low=0.0, doc='standard deviation of the '
                                 'control probing noise on the first leg')
    probing_decay: float = setting(0.85, low=0.0, low_open=True, high=1.0, doc='factor '
                                   'applied to the probing standard deviation after every leg')
    probing_floor: float = setting(0.0, unit='N', low=0.0,
                                   doc='lower bound of the probing standard deviation')
    probing_correlation: float = setting(1.0, unit='s', low=0.0, doc='correlation time of the '
                                         'probing noise (Ornstein-Uhlenbeck); 0: white noise')
    """Slow probing moves the robot (excites velocities) where white noise at 1/Δt averages
    out in the plant; the off-policy critic needs no whiteness."""
    measured_disturbance: bool = setting(False, doc='nominal variant: the critic takes the '
                                         'measured disturbance (/disturbance) into its rows '
                                         'as an input it does not choose (a robot with a '
                                         'disturbance sensor); false: not read')
    """No robot has the simulator's /disturbance: wind, a slope or a payload is felt, not
    published. ``true`` is for a robot that has a sensor of it (or the simulator's oracle);
    without it the observer (``observer``) estimates what the rows need."""
    observer: bool = setting(True, doc='nominal variant without measured_disturbance: the '
                             'critic learns from the equivalent input of each step (the '
                             'applied force plus the matched disturbance) and, with noisy '
                             'odometry, smoothed states, both from a one-step model '
                             'identified from odometry and the applied forces; false: from '
                             'the odometry and the commanded force as they are (the papers)')
    """:mod:`rrtq_controller.observer`. Without it an unmeasured disturbance, odometry noise or
    an actuation delay biases the critic's rows and the guard rejects every proposal (the
    rover without a spring under 0.5 m/s² of white noise held the zero gain for 400 s)."""
    disturbance_estimate: bool = setting(False, doc='robust variant: play the game against '
                                         'the disturbance the observer estimates (the matched '
                                         'push, in N per input), not the measured '
                                         '/disturbance (the paper assumes it measured); gamma '
                                         'then in cost units per N')
    """ACC 2019 learns the game from the disturbance that acted, measured. A robot that does
    not measure its disturbance can play against the equivalent input disturbance its
    observer identifies (:meth:`rrtq_controller.observer.Observer.acted`): m components, in
    the units of the forces, entering where the forces do (a matched disturbance)."""
    friction_compensation: bool = setting(False, doc='opt-in, with the observer: where it has '
                                          'identified Coulomb friction, add the friction '
                                          'level per axis in the direction of motion (at '
                                          'rest: of the force), so that the robot moves '
                                          'as its linear part would')
    """Coulomb friction compensation from the identified friction
    (:meth:`rrtq_controller.observer.Observer.friction`); false: none. Opt-in: under odometry
    noise, a delay and a sinusoid the friction columns' test calls friction that is not
    there (levels up to 14 N, bound 6.6 N, on a frictionless rover), and a compensation
    switching with the sign of a noisy speed cost a mission its goal (400 s against 179 s)."""
    integral_action: bool = setting(True, doc='on a leg that follows one which ran its '
                                    'horizon short of its window, add a force toward the '
                                    'waypoint that grows by force_limit / T per second along '
                                    'each axis the robot is held on (slower along it, by more '
                                    'than odometry noise explains at 1 %, than it needs to '
                                    'reach the window in the time left of the leg), not while '
                                    'a keep-off pushes (false: off)')
    """Conditional integral action (:mod:`rrtq_controller.held_short`): a steady push or
    Coulomb friction holds any linear state feedback short of its waypoint (the MuJoCo plant
    with friction μ = 0.1 and 0.3: 0/20 goals without it). On by default since the held
    test allows for the odometry's noise and asks for the speed that reaches the window in
    the time left (docs/features.md, issue 32, for the measurements)."""
    push_feedforward: bool = setting(False, doc='nominal variant with the observer: add to '
                                     'the policy\'s force the force that cancels the push '
                                     'the observer predicts from the low-pass filtered push '
                                     'it reads (a disturbance observer; push_filter_time); '
                                     'experimental, off by default')
    """Integral action, model-free toward the plant: without it a steady push F_d (a field, a
    slope, Coulomb friction) holds a robot F_d / K_p short of its waypoint, and a slow
    sinusoid moves it by what the feedback alone leaves. Only the predictable part is fed
    forward (nothing of a white push). Off by default: under odometry noise a push read at
    rest through a model biased by errors in variables pushed a robot out of the bounds,
    and on a plant with Coulomb friction it winds up or never starts (docs/observer.md §6)."""
    push_feedforward_law: PushLaw = setting(PushLaw.OPTIMAL, doc='push_feedforward: optimal '
                                            '(the LQ-optimal feed-forward of the predicted '
                                            'push) | cancel (minus the predicted push)')
    """Against a steady push the two agree (the whole push, integral action); against a
    periodic one cancelling costs more than letting it act, the LQ-optimal one about half
    of what the feedback alone pays (``test_lq_feedforward.py``)."""
    push_filter_time: float = setting(0.25, low=0.0, low_open=True, unit='s',
                                      doc='push_feedforward: time constant of the low-pass '
                                      'filter of the push')
    observer_lags: int = setting(3, low=0, doc='observer: input lags of the one-step model '
                                 '(steps); an actuation delay of up to this many steps is '
                                 'identified')
    observer_memory: int = setting(4000, low=100, doc='observer: steps of odometry the '
                                   'one-step model is identified from')
    observer_ar: int = setting(2, low=0, doc='observer: order of the AR model of the '
                               'unexplained part of each step (2: a sinusoid)')
    disturbance_probing_std: float = setting(0.1, low=0.0, doc='standard deviation of the '
                                             'disturbance-actor probing noise on the first '
                                             'leg (robust)')
    initial_gain: tuple[tuple[float, ...], ...] | None = setting(
        None, rows='m', doc="K0 (m x n), the actor's initial gain, u = -K0 x_bar (N per state "
        'unit); None: 0')
    """Policy evaluation needs a policy whose value the time basis can represent: on a plant
    that is not stable by itself (the rover without a spring) give a PD gain brisk enough
    to reach the window D <= ρ D0 within T (e.g. 40 N/m, 30 N s/m for the 40 kg rover); a
    sluggish one (10 N/m, 20 N s/m) runs whole horizons, its value varies on time scales
    the basis lacks, and the critic's fit of it is not trusted (see policy_evaluation).
    """
    critic_memory: int = setting(2000, low=1, doc='least squares: number of stored Δt samples '
                                 'the critic is fitted to (a window)')
    evaluation_period: float = setting(2.0, unit='s', **_POSITIVE, doc='least squares: time '
                                       'between policy evaluations within a leg (also at leg '
                                       'starts)')
    ridge: float = setting(1e-6, low=0.0, doc='least squares: ridge weight, relative to the '
                           'mean diagonal of the normal matrix')
    stability_delta: float = setting(1.0, **_POSITIVE, doc='δ, δ1, δ2 of the stability bounds '
                                     '(RRT-QX (25), ACC Theorem 2): constants of unity order')
    force_limit: float = setting(math.inf, unit='N', low=0.0, low_open=True, doc="the "
                                 "actuator's limit per axis (a specification, not the "
                                 'dynamics): every command is saturated to it; inf: none')
    """The Bellman rows are formed with the saturated force, the one the actuator applied,
    so that the off-policy critic stays consistent when the limit binds. The scenario's
    default is the plant's ``force_limit``."""
    probing_across: float = setting(1.0, low=0.0, high=1.0, doc='fraction of the probing '
                                    'standard deviation applied across the leg (the rest '
                                    'along it); 1: isotropic')
    probing_line_fraction: float = setting(0.1, low=0.0, doc='guard: beyond this fraction of '
                                           "the leg's length from its line, probing that "
                                           'points away from the line is turned toward it; '
                                           'inf: never')
    """Beyond the papers (:meth:`probing.Probing.sample`): a weak early policy leaves the
    robot to the probing, which walks it off its line. On the 40 random plants of the
    robustness bench, 11 had a leg more than half its length off its line; with the probing
    turned toward the line beyond 0.1 of the length, 4 (one of them under the true Riccati
    policy too; 0.2: 5), at a price: 19 plants within 5 % instead of 21 (all disturbed), and
    in the closed loop one 110 kg and one 120 kg run above 1.05
    (docs/notes/2026-12-02-safe-learning-from-defaults.md)."""
    max_fit_residual: float = setting(0.3, **_POSITIVE, doc='guard: largest relative residual '
                                      'of the critic fit for which its proposal is adopted')
    """√(Σ w e²) / √(Σ w y²) over the Bellman rows (see :func:`critic.fit`); beyond the papers,
    like every guard setting (:meth:`QLearningController.policy_improvement`)."""
    value_tolerance: float = setting(0.01, **_POSITIVE, doc="guard: largest negative part of a "
                                     "policy's value on the stored samples, as a fraction "
                                     'of the sum of its absolute values')
    coverage_quantile: float = setting(0.02, low=0.0, high=1.0, doc='guard: the proposal is '
                                       'followed only at times-to-go above this quantile of '
                                       "the stored samples' (held at its value there below)")
    """Where the critic has no data its greedy gain is the time basis' extrapolation
    (:func:`guard.held_below`); 0: follow it on the whole horizon (the papers)."""
    rollout_test: bool = setting(True, doc='guard, with the observer: a proposal that '
                                 'carries a robot at rest farther from its target than the '
                                 'current policy does, flown through the identified model, '
                                 'is not adopted')
    """Reads a proposal through the plant as identified, not through the critic that proposed
    it (:mod:`rrtq_controller.rollout`); false: the guard without it."""
    trust_growth: float = setting(1.0, **_POSITIVE, doc='guard: trust region of one adoption, '
                                  '|dK(τ)| <= trust_growth max(|K(τ)|, K_floor)')
    """The gain may grow by this factor per adoption (1: double), from a floor set by the
    probing scale (see :meth:`QLearningController.policy_improvement`); a longer step is
    shortened to that length."""
    divergence_distance: float = setting(2.0, **_POSITIVE, doc='guard: a leg diverges when D '
                                         '> divergence_distance D0 + divergence_floor')
    divergence_floor: float = setting(1.0, low=0.0, doc='guard: state units (m, m/s) added '
                                      'to both divergence bounds')
    """So that a leg that starts at its target (D0 ≈ 0: holding station) is not declared
    diverged by probing alone."""
    divergence_speed: float = setting(4.0, **_POSITIVE, doc='guard: a leg also diverges when '
                                      'the speed exceeds divergence_speed (L + |v0| T) / T '
                                      '+ divergence_floor (L the leg length, v0 its initial '
                                      'velocity)')
    divergence_deviation: float = setting(0.25, unit='m', low=0.0, doc='guard: a leg also '
                                          'diverges when the robot is farther from its line '
                                          'than the widest distance of the legs before it '
                                          '(the running-max margin) plus this; the controller '
                                          'then brakes to rest (inf: off)')
    """Beyond the margin the obstacles of the current plan were grown by, the plan no longer
    keeps the robot clear (:class:`guard.DivergenceWatch`); stopping lets the safety node
    grow them and the planner plan again from where the robot is."""
    safe_hold: SafeHold = setting(SafeHold.BRAKE, doc='guard: what a leg that diverged before '
                                  'any policy completed a leg holds: brake | initial')
    """The initial policy is the zero gain unless ``initial_gain`` is given, and a lightly
    damped robot coasts on under it (:class:`guard.Brake`)."""
    hold_stop_time: float = setting(1.0, unit='s', **_POSITIVE, doc='guard: the brake doubles '
                                    'its force while the speed falls slower than to stop '
                                    'within this time')
    keep_off: float = setting(0.3, unit='m', low=0.0, doc='guard: within this distance of '
                              'the nearest detected obstacle or of the one ahead along the '
                              'velocity (/safety/status), an approach to it is pushed back '
                              '(learning variants; 0: off)')
    """:class:`guard.KeepOff`; needs the safety node's /safety/status (lock-step: of the same
    step), which the learning controller then waits for."""
    forces: tuple[tuple[float, float, float], ...] = setting(
        (), columns=3, doc='open_loop: the force profile, rows [t (s), f_x (N), f_y (N)], '
        'piecewise constant from each t')
    goal: tuple[float, float] = setting((0.0, 0.0), unit='m', doc="open_loop: the run's goal, "
                                        'its leg target (D and D0 are measured to it)')
    model: str = setting('', doc='vf_lpc: the nominal model file written by rrtq identify '
                         '(absolute path; the scenario gives it relative to its file)')
    stale_timeout_s: float = setting(0.5, unit='s', low=0.0, doc='paced mode: wall time '
                                     'without odometry after which the controller commands '
                                     'zero force')

    def __post_init__(self) -> None:
        check(self)
        if self.dt >= self.horizon:
            raise ValueError('need 0 < dt < horizon')
        if not self.time_rates or self.time_rates[0] != 0.0:
            raise ValueError('time_rates must start with 0.0 (the constant function)')
        if any(int(k) != k for k in (*self.time_powers, *self.widen_powers)):
            raise ValueError('time_powers and widen_powers must be integers >= 1')
        if self.variant is Variant.ROBUST and self.gamma is None:
            raise ValueError('gamma is required for the robust variant')

    @property
    def reads_disturbance(self) -> bool:
        """Whether the controller learns from the measured disturbance (/disturbance).

        The robust variant unless it plays against the observer's estimate
        (``disturbance_estimate``); the nominal one when ``measured_disturbance``.
        """
        return ((self.variant is Variant.ROBUST and not self.disturbance_estimate)
                or (self.variant is Variant.NOMINAL and self.measured_disturbance))

    @property
    def cancels_push(self) -> bool:
        """Whether the policy's force carries the push feed-forward (nominal, observing)."""
        return self.push_feedforward and self.observes and self.variant is Variant.NOMINAL

    @property
    def observes(self) -> bool:
        """Whether the critic learns through the observer.

        Nominal: when the disturbance is not read; robust: when it is estimated.
        """
        if self.variant is Variant.ROBUST:
            return self.disturbance_estimate
        return self.observer and self.variant is Variant.NOMINAL and not self.measured_disturbance

    @property
    def gains(self) -> Gains:
        """The gains in use: those given, the controller's choice for the others."""
        given = {name: getattr(self, name) for name in ('alpha_c', 'alpha_a', 'alpha_d')}
        return Gains(**{name: value for name, value in given.items() if value is not None})

    def expanded(self, n: int, m: int) -> ControllerConfig:
        """Return a copy whose M, R, P_T are full, validated, read-only matrices."""
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
    keep_off: float = 0.0
    """N: the pushes away from the nearest detected obstacle and from the one ahead along the
    velocity added this step (guard.KeepOff, guard.face_ahead)."""
    policy_event: str = ''
    """What the guard did this step: '' (nothing), or :class:`guard.PolicyEvent` values
    joined by ';' (an evaluation at a leg start can both reject and revert)."""
    policy_reason: str = ''
    """Why (the check that failed, the divergence criterion), '; '-joined like the events."""
