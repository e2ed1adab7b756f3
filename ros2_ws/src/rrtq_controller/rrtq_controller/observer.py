"""What the robot can measure, made fit to learn from: a one-step model of its own motion.

The integral Bellman rows (:mod:`bellman`) hold exactly only when every input that moved
the robot over a step is in them. A robot measures its odometry and knows the forces it
commanded; it does not measure the wind, a slope, a payload or a tug, its odometry is
noisy, and its actuator may apply a command a few steps late. Each of these breaks the
rows, and a least-squares critic fitted to broken rows is biased however much data it
gets (docs/design.md, "Learning from what a robot can measure"):

* an unmeasured disturbance w enters the Bellman row of the true Q-function as
  ∫ x̄ᵀ P F w dτ; for a *matched* disturbance (F = B G, a force-like push, as wind, slope
  and payload are on a wheeled or legged base) that is ∫ x̄ᵀ Q_xu G w dτ, the very term
  the probing enters the rows by (x̄ᵀ Q_xu (u - û)): if G w were known, adding it to the
  applied force would make the rows exact again;
* a delayed actuator applies u_{k-j}, not u_k, over step k;
* odometry noise puts errors into both sides of the rows (errors in variables).

This module identifies, from odometry and the commanded forces alone (no A, B given), the
linear one-step model of the robot in its leg coordinates,

    x̄_{k+1} = Φ x̄_k + Σ_{j=0..J} Γ_j u_{k-j} + e_k,

the input lags covering an actuation delay of up to J steps, by least squares with the
disturbance e modelled as an AR(p) process (iterated Cochrane-Orcutt: a sinusoid is an
AR(2) process, white noise AR(0), a field the robot drives through nearly AR(2)); without
the AR part a slow disturbance correlated with the state biases Φ. With odometry noise
(the covariance the odometry reports), the states are smoothed by a Rauch-Tung-Striebel
smoother on that model before the identification and before the rows are formed, and the
model is identified again on the smoothed states at the next evaluation (one EM-like
pass per evaluation). The critic then learns from the smoothed states and from the
*equivalent input* of each step,

    u_eff,k = Γ⁺ (x̂_{k+1} - Φ x̂_k),   Γ = Σ_j Γ_j,

the force that explains the step: the applied (possibly delayed) force plus the matched
part of the disturbance. Only the learning sees the estimates; the robot is controlled
from its odometry as measured. Beyond the papers (RRT-QX assumes the state measured and
no disturbance; ACC 2019 assumes the disturbance measured).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solve_discrete_are
from scipy.signal import lfilter
from scipy.stats import chi2, norm

Array = NDArray[np.float64]

RIDGE = 1e-9
"""The ridge of :meth:`Observer.identify`, per standardised unit and transition."""
GAMMA_FALSE_ALARM = 0.01
"""Two-sided rate at which Γ's error exceeds :attr:`OneStepModel.gamma_error`'s allowance."""
_Z_ONE_SIDED = float(norm.ppf(1.0 - GAMMA_FALSE_ALARM))
"""The one-sided normal quantile at :data:`GAMMA_FALSE_ALARM` (the friction level's bounds)."""
AR_ITERATIONS = 4
"""Cochrane-Orcutt iterations of :meth:`Observer.identify`, from zero AR coefficients or,
with ``reads_pushes``, from the last model's. Where the forces are a feedback of the state
they settle in 2-3 from zero. With the push feed-forward the force carries the
disturbance's own estimate, least squares without the AR part is far off, and from zero
they took 6-8 (a 0.2 Hz sinusoid: (1.87, -0.88) after four against (1.996, -1.000)); more
iterations from zero drift on exact data (a unit root that filters everything away), so
there each identification goes on from the last."""


@dataclass(frozen=True)
class OneStepModel:
    """x̄_{k+1} = Φ x̄_k + Σ_j Γ_j u_{k-j} + e_k, in leg coordinates; e AR(p) with coefficients ``ar``."""

    phi: Array
    """Φ (n x n)."""
    gammas: Array
    """Γ_j (J + 1, n, m): the force of j steps ago."""
    ar: Array
    """a_1..a_p of e_k = Σ a_i e_{k-i} + ε_k (common to every state component)."""
    residual_cov: Array
    """(n x n): covariance of e, the part of a step the forces and the state do not explain."""
    friction: Array | None = None
    """C (n x m): the effect over a step of Coulomb friction, sign(v_i) per velocity
    component (:meth:`Observer._coulomb`); None where the data do not show it. Part of e
    (a push: what the forces and the state do not explain), not of u_eff's model."""
    friction_level: Array | None = None
    """N per input: the friction level, -(Γ_v⁻¹ C_v)_ii (None with :attr:`friction`)."""
    friction_error: Array | None = None
    """N per input: the standard error of :attr:`friction_level`."""
    steady: Array | None = None
    """(n,): the constant column's effect over a step (a steady push), as fitted."""
    gamma_error: float = math.inf
    """How far Γ may be off, relative (assessed only for an observer that ``reads_pushes``;
    inf: not assessed, no push is read through the model): z ‖SE(Γ)‖_F / σ_min(Γ) (z at :data:`GAMMA_FALSE_ALARM`,
    SE from the fit's covariance) plus the share by which the ridge shrinks the least
    determined direction of the regression, λ / (s_min + λ) (1 where the data do not
    determine the model: forces that only ever were a feedback of the state). A
    disturbance-observer loop on this model is stable while it is below 1
    (:class:`PushCanceller`)."""

    @property
    def gamma(self) -> Array:
        """Γ = Σ_j Γ_j (n x m): the whole effect of a force held over a step."""
        return np.asarray(self.gammas.sum(axis=0), dtype=float)

    @property
    def delay(self) -> int:
        """The lag j (steps) of the largest Γ_j: the actuation delay the data show."""
        return int(np.argmax(np.linalg.norm(self.gammas, axis=(1, 2))))

    def forced(self, u: Array) -> Array:
        """Σ_j Γ_j u_{k-j} for every step k of forces u in time order (zero before the first)."""
        lags = self.gammas.shape[0] - 1
        return np.asarray(_lagged(u, lags) @ self.gammas.transpose(0, 2, 1).reshape(-1, self.phi.shape[0]),
                          dtype=float)

    def equivalent_input(self, x0: Array, x1: Array, forced: Array | None = None) -> Array:
        """u_eff = Γ⁺(x̄1 - Φ x̄0 - f) for batches (N, n): the force that explains each step.

        ``forced`` f (N, n): the forces' part of the steps (:meth:`forced`), taken off first:
        then what is left is the matched push (:meth:`Observer.last_push`).
        """
        e = x1 - x0 @ self.phi.T
        if forced is not None:
            e = e - forced
        return np.asarray(np.linalg.lstsq(self.gamma, e.T, rcond=None)[0].T, dtype=float)


class Observer:
    """The robot's log of odometry and commands, its one-step model, and smoothed states.

    Parameters
    ----------
    n, m
        State and input dimensions.
    lags
        J: input lags of the model (an actuation delay of up to J steps is identified).
    memory
        Steps of odometry kept; the model is identified from them.
    ar
        p: order of the AR model of the unexplained part of each step.
    """

    def __init__(self, n: int, m: int, lags: int = 3, memory: int = 4000, ar: int = 2,
                 reads_pushes: bool = False, velocity: slice | None = None) -> None:
        self.n, self.m, self.lags, self.ar = n, m, lags, ar
        self.velocity = velocity
        """The states that are the velocity, one per input (the rover's x̄ = (p̄, v):
        ``slice(m, 2m)``), for the Coulomb friction columns (:meth:`_coulomb`); None: none."""
        self.reads_pushes = reads_pushes
        """Whether pushes are read through its models (:meth:`last_push`, the push
        feed-forward, whose forces then carry the push's estimate): each identification's AR
        iterations also start from the last model's coefficients (:data:`AR_ITERATIONS`) and
        the model carries its :attr:`OneStepModel.gamma_error`; neither costs the
        identification anything otherwise."""
        self._y = np.zeros((memory, n))
        self._u = np.zeros((memory, m))
        self._segment = np.zeros(memory, dtype=np.int64)
        self._fits = np.ones(memory, dtype=bool)
        self._sensitivity = np.zeros((memory, m, n))
        self.steps = 0
        """Steps recorded since the start (the id of the next one)."""
        self.variance = np.zeros(n)
        """Variance of each state's measurement (the odometry's covariance diagonal)."""
        self.model: OneStepModel | None = None
        self._push_noise: tuple[OneStepModel, float, bytes, Array] | None = None
        """:meth:`push_noise`'s last (model, a, variance, value): it changes with them only."""
        self._smoothed: Array | None = None
        self._acted = np.zeros((0, m))
        self._smoothed_segment = np.zeros(0, dtype=np.int64)
        self._first = 0
        """Step id of the first row of :attr:`_smoothed`."""

    @property
    def memory(self) -> int:
        """Steps kept."""
        return len(self._y)

    def record(self, y: Array, u: Array, segment: int, fits: bool = True,
               sensitivity: Array | None = None) -> int:
        """Log the measured state y (leg coordinates) and the force commanded after it.

        ``segment`` changes whenever the leg coordinates do (a new leg or horizon): a
        transition is learned only within one. ``fits``: whether the model may be
        identified from the transition this step begins (it is smoothed, estimated and read
        all the same). ``sensitivity`` (m x n): ∂u/∂y, how the force followed the measured
        state (a state feedback's -K; None: not at all), through which odometry noise
        enters the force (:func:`_noise_bias`). Returns the step's id.
        """
        i = self.steps % self.memory
        self._y[i], self._u[i], self._segment[i], self._fits[i] = y, u, segment, fits
        self._sensitivity[i] = 0.0 if sensitivity is None else sensitivity
        self.steps += 1
        return self.steps - 1

    def _ordered(self) -> tuple[Array, Array, NDArray[np.int64], int]:
        """(y, u, segment) of the kept steps in time order, and the id of the first."""
        count = min(self.steps, self.memory)
        first = self.steps - count
        idx = (np.arange(count) + first) % self.memory
        return self._y[idx], self._u[idx], self._segment[idx], first

    # ------------------------------------------------------------ identification
    def identify(self, x: Array, u: Array, segment: NDArray[np.int64],
                 ar: int | None = None, fits: NDArray[np.bool_] | None = None,
                 noise: tuple[Array, Array] | None = None,
                 weights: OneStepModel | None = None) -> OneStepModel | None:
        """The one-step model from states x (raw or smoothed) and forces u in time order.

        Least squares of x̄_{k+1} on (x̄_k, u_k, ..., u_{k-J}) over the transitions within
        a segment, with e AR(p)-filtered out (Cochrane-Orcutt, :data:`AR_ITERATIONS`
        times); regressors standardised so that forces (N) and states (m) are alike.
        None when there are fewer than ten transitions per unknown. ``fits``: per step, whether
        the transition it begins may be used (with the p before it), all by default. ``ar``: p, by default
        the observer's. ``noise`` (the variance of each state's measurement, and each step's
        ∂u/∂y, :meth:`record`): x is measured with that white noise, and the fit (then
        without AR part or Coulomb columns) is corrected for it (:func:`_noise_bias`).
        ``weights``: Φ, the Γ_j and the constant of that model are kept, and only the AR part
        and the residual's covariance are fitted (no Coulomb columns).
        """
        n, m, J = self.n, self.m, self.lags
        p = self.ar if ar is None else ar
        lagged = _lagged(u, J)
        if self.velocity is not None and not self.noisy:
            # a component held at rest while a force acts on it (friction up to its level,
            # or a push that balances the force) shows no effect of that force: fitted, such
            # transitions pull Γ toward zero (at mu = 0.3 Γ came out at 0-20 % of the plant's
            # and Φ's velocity part near zero, and the guard flew proposals through that).
            # Only with exact odometry: with noise "at rest" is within 2.6 σ_v (0.13 m/s at
            # σ_v = 0.05), which a slow robot is on most steps, and leaving those out left
            # a robot under the zero gain and its probing no model for 400 s (robot_side's
            # noisy, delayed, undisturbed row, seeds 14-16: 195 rejections, no goal)
            v, rest = x[:, self.velocity], self.rest()
            held = np.any((np.abs(v[:-1]) <= rest) & (np.abs(v[1:]) <= rest)
                          & (u[:-1] != 0.0), axis=1)
            fits = np.ones(len(x), dtype=bool) if fits is None else fits.copy()
            fits[:-1] &= ~held
        # a constant column takes a steady push (a slope, a payload), which otherwise the
        # states it displaced would explain in part, biasing Φ; it stays in the residual
        regress = np.hstack([x[:-1], lagged[:-1], np.ones((len(x) - 1, 1))])
        target = x[1:]
        same = segment[1:] == segment[:-1]
        usable = _with_the_p_before(same, p)   # and the p transitions before in the segment
        usable[:max(p, J)] = False        # the p before, and the lags, of the first unknown
        if fits is not None:              # and none of them kept out (Observer.record)
            fitted = _with_the_p_before(fits[:-1], p)
            usable &= fitted
            same = same & fitted
        if usable.sum() < 10 * regress.shape[1]:
            return None
        # from zero AR coefficients and, with reads_pushes, also from the last model's where it
        # had as many (the iterations go on from where the last identification left them):
        # the fit of the larger likelihood
        starts = [np.zeros(p)]
        last = self.model.ar if self.model is not None and self.reads_pushes else np.zeros(0)
        if p and len(last) == p and np.all(np.isfinite(last)) and np.any(last):
            starts.append(last.copy())
        if weights is not None:
            w = _weights(weights)
            a = _ar_coefficients(target - regress @ w, usable, p) if p else np.zeros(0)
        elif noise is not None:
            bias = _noise_bias(noise[0], noise[1][:-1][usable], regress.shape[1])
            w = _least_squares(regress[usable], target[usable], bias, n)
            a = np.zeros(0)
        else:
            candidates = [_cochrane_orcutt(regress, target, usable, p, a) for a in starts]
            w, a, _ = min(candidates, key=lambda fit: fit[2])
        if not np.all(np.isfinite(w)):
            return None                   # no model in data that cannot give one
        friction = level = error = None
        if self.velocity is not None and noise is None and weights is None:
            coulomb = self._coulomb(x, lagged, segment, usable, p, a, fits)
            if coulomb is not None:
                regress, usable, w, a, (friction, level, error) = coulomb
        k = n + (J + 1) * m               # Φ and the Γ_j; the Coulomb and steady parts follow
        e = (target - regress[:, :k] @ w[:k])[same]     # the steady push (and friction) included
        gammas = _gammas(w, n, m, J)
        gamma_error = (_gamma_error(_ar_filter(regress, a)[usable], _ar_filter(target, a)[usable],
                                    w, n, m, J) if self.reads_pushes else math.inf)
        return OneStepModel(phi=w[:n].T.copy(), gammas=gammas, ar=a,
                            residual_cov=np.atleast_2d(np.cov(e.T)), gamma_error=gamma_error,
                            steady=w[-1].copy(),
                            friction=friction, friction_level=level, friction_error=error)

    def _coulomb(self, x: Array, lagged: Array, segment: NDArray[np.int64], usable: NDArray[np.bool_],
                 p: int, a0: Array, fits: NDArray[np.bool_] | None
                 ) -> tuple[Array, NDArray[np.bool_], Array, Array,
                            tuple[Array, Array, Array]] | None:
        """The fit with Coulomb friction where the data show it.

        (regressors, usable, W, AR, (C, the level F̂ per input, its standard error)).

        Coulomb friction resists a moving robot with a force of constant size against each
        velocity component, an input the linear model has not: least squares reads it as
        damping (at the low speeds the robot learns at, a relay looks like a steep viscous
        term), and a critic learning through a model that damps more than the plant learns
        a policy that cancels the surplus with an anti-damping velocity gain, which throws
        the robot once it moves fast (MuJoCo, mu = 0.3: -371 N s/m, 6.5 m/s within a
        second, a contact). So the transitions get a column sign(v_i) per velocity
        component i (0 within the speed odometry noise makes at the false-alarm rate:
        :meth:`rest`), their coefficients C the friction's effect over a step, and the
        transitions where a component stands still at both ends are left out of this fit
        (whatever holds a robot at rest, friction up to its level, balances the force of
        the moment, not a constant: the free motion under that force is not in them).
        Kept only where the data call C at :data:`GAMMA_FALSE_ALARM` (a Wald test on its
        velocity rows, χ² with m² degrees of freedom) and the levels they give can be
        friction (:func:`_friction_like`: none negative, one positive, none beyond the forces
        that moved the robot): on a plant without friction the model is the one without the
        columns (but at that rate). The Wald test alone assumes regressors without error;
        under odometry noise (0.05 m/s) and a 2-step delay it called levels of -15 N with a
        velocity Φ of 0.82 (the plant's 0.945) in 3 of 17 identifications of a frictionless
        rover's run, 9 of 18 in another, and a critic learning through such a model (more
        damping than the plant) learns an anti-damping gain. Model-free toward the plant
        like the rest of the fit: the columns are functions of the measured velocity, as the
        constant is.
        """
        n, m = self.n, self.m
        assert self.velocity is not None
        rest = self.rest()
        v = x[:, self.velocity]
        sign = np.where(np.abs(v) > rest, np.sign(v), 0.0)
        steady = np.all(sign[:-1] * sign[1:] > 0, axis=1)   # every component moving one way
        moving = steady if fits is None else (fits[:-1] & steady)
        use = usable & _with_the_p_before(moving & (segment[1:] == segment[:-1]), p)
        base = n + (self.lags + 1) * m
        regress = np.hstack([x[:-1], lagged[:-1], sign[:-1],
                             np.ones((len(x) - 1, 1))])
        if use.sum() < 10 * regress.shape[1]:
            return None
        w, a, likelihood = _cochrane_orcutt(regress, x[1:], use, p, a0)
        if not (np.all(np.isfinite(w)) and math.isfinite(likelihood)):
            return None
        Z, E = _ar_filter(regress, a)[use], _ar_filter(x[1:] - regress @ w, a)[use]
        block = slice(base, base + m)
        # (ZᵀZ)⁻¹ through standardised columns with the fit's ridge: a sign column the data
        # make collinear (a robot that only ever moved one way: sign = the constant) gets
        # the variance of what the data do not determine, and no call
        inverse = _ridge_inverse(Z)[0][block, block]
        # the test on the velocity rows, where friction acts (a position row's noise is the
        # velocity row's, integrated: summing both would count it twice): vec(C_v) has the
        # covariance Σ_v ⊗ (ZᵀZ)⁻¹_CC, so W = tr(Σ_v⁻¹ C_vᵀ (ZᵀZ)⁻¹_CC⁻¹ C_v) is χ²(m²) without
        # friction; exact data leave a residual of rounding alone, against which any C is
        # significant: Σ_v is at least that of a relative precision of 1e-9 of the speeds
        C = w[block]                                   # (m, n): column i's effect on x̄
        Cv, Ev = C[:, self.velocity], E[:, self.velocity]
        floor = (1e-9 * np.sqrt(np.mean(x[1:][use][:, self.velocity] ** 2, axis=0))) ** 2
        sigma = Ev.T @ Ev / len(Ev) + np.diag(floor)
        try:
            information = np.linalg.inv(inverse)
            wald = float(np.trace(np.linalg.solve(sigma, Cv.T @ information @ Cv)))
        except np.linalg.LinAlgError:
            return None
        if not math.isfinite(wald) or wald <= chi2.ppf(1.0 - GAMMA_FALSE_ALARM, m * m):
            return None
        # the friction per unit of force, F_i = -(Γ_v⁻¹ C_v)_ii, and its standard error:
        # Var((Γ_v⁻¹ C_v)_ki) = (ZᵀZ)⁻¹_ii (Γ_v⁻¹ Σ_v Γ_v⁻ᵀ)_kk (Γ's own error left out)
        gamma_v = _gammas(w, n, m, self.lags).sum(axis=0)[self.velocity]
        try:
            per_force = np.linalg.solve(gamma_v, Cv.T)
            spread = np.linalg.solve(gamma_v, np.linalg.solve(gamma_v, sigma).T)
        except np.linalg.LinAlgError:
            return None
        level = -np.diag(per_force)
        error = np.sqrt(np.maximum(np.diag(inverse) * np.diag(spread), 0.0))
        if not _friction_like(level, error, _largest_force(lagged[:-1][use], m)):
            return None
        return regress, use, w, a, (np.asarray(C.T, dtype=float), np.asarray(level, dtype=float),
                                    np.asarray(error, dtype=float))

    def friction(self) -> Array | None:
        """N per input: the Coulomb friction the data show at least (None: none identified).

        The lower one-sided confidence bound of the identified level at
        :data:`GAMMA_FALSE_ALARM`, F̂ - z SE (at least 0): compensated by more than its
        friction a robot is pushed on along its motion, a positive feedback; by less, what
        is left acts as friction does. A level the data barely determine (a robot that
        moved one way only: the sign column is the constant's) has a large SE and no bound.
        """
        model = self.model
        if model is None or model.friction_level is None or model.friction_error is None:
            return None
        return np.asarray(np.maximum(model.friction_level - _Z_ONE_SIDED * model.friction_error,
                                     0.0),
                          dtype=float)

    def rest(self) -> Array:
        """m/s per velocity component: the speed below which it counts as standing still.

        Two-sided normal quantile of the odometry's σ_v at :data:`GAMMA_FALSE_ALARM`; with
        exact odometry 1e-9 m/s (zero to the precision of a simulator's solver: a MuJoCo base
        held by its friction loss shows 1e-12 m/s).
        """
        assert self.velocity is not None
        sigma = np.sqrt(self.variance[self.velocity])
        return np.maximum(norm.ppf(1.0 - GAMMA_FALSE_ALARM / 2) * sigma, 1e-9)

    def update(self) -> bool:
        """Identify the model from the kept steps; smooth the states with it if odometry is noisy.

        With noisy odometry the model is first identified on the measured states with no
        AR part, corrected for the noise (corrected least squares, :func:`_noise_bias`: the
        odometry's variance and how the forces followed the measured state), which never
        depends on an earlier estimate; the states are smoothed with it, and on the smoothed
        states its Φ and Γ_j are kept and the AR part fitted to what they leave (on measured
        states an AR filter close to a difference would amplify the noise it should not see).
        Refitting Φ and Γ on the smoothed states, as before, biased Γ upward (the smoother's
        errors are not white and the forces followed the noise): 17-37 % with 10 N of
        probing and 70-200 % with 4 N, against 0-9 % and 0-24 % corrected (a PD-held rover,
        σ_v = 0.05 m/s fed back, a 2-step delay; ``test_observer.py``). Where the smoothed
        states show Coulomb friction (:meth:`_coulomb`) the refit with its columns is kept
        instead (friction's own bias on Φ, Γ is the larger) and the states are smoothed
        again with it; otherwise the model kept has the same Φ and Γ_j, and the states
        smoothed with them stand. Returns whether there is a model.
        """
        y, u, segment, first = self._ordered()
        if len(y) < self.lags + self.ar + 2:
            return self.model is not None
        kept = (np.arange(len(y)) + first) % self.memory
        fits = self._fits[kept]
        noise = (self.variance, self._sensitivity[kept]) if self.noisy else None
        model = self.identify(y, u, segment, ar=0 if self.noisy else None, fits=fits,
                              noise=noise)
        if model is None or not _invertible(model.gamma):
            return self.model is not None
        if self.noisy:
            smoothed = self._smooth(model, self._process_noise(model, y, u, segment), y, u,
                                    segment)
            refined = self.identify(smoothed, u, segment, fits=fits)
            if (refined is not None and refined.friction is not None
                    and _invertible(refined.gamma)):
                model = refined
                smoothed = self._smooth(model, self._process_noise(model, y, u, segment), y, u,
                                        segment)
            else:   # the same Φ, Γ_j: the states smoothed with them stand
                model = self.identify(smoothed, u, segment, fits=fits, weights=model) or model
        self.model = model
        self._smoothed = smoothed if self.noisy else y.copy()
        # the force that acted over each step, as the model sees it: Γ⁺ Σ_j Γ_j u_{k-j}
        self._acted = np.asarray(np.linalg.lstsq(model.gamma, model.forced(u).T, rcond=None)[0].T,
                                 dtype=float)
        self._smoothed_segment, self._first = segment.copy(), first
        return True

    @property
    def noisy(self) -> bool:
        """Whether the odometry reports a measurement variance (then states are smoothed)."""
        return bool(np.any(self.variance > 0.0))

    def estimates(self, steps: NDArray[np.int64]) -> tuple[Array, Array, Array, NDArray[np.bool_]]:
        """Smoothed x̄ at each step and the next, the equivalent input between, and which exist.

        For transitions whose steps are not both in the last :meth:`update`'s smoothing
        (too old, or recorded since), or cross a segment, the mask is False.
        """
        k = len(steps)
        x0, x1, u = np.zeros((k, self.n)), np.zeros((k, self.n)), np.zeros((k, self.m))
        if self.model is None or self._smoothed is None:
            return x0, x1, u, np.zeros(k, dtype=bool)
        rel = steps - self._first
        ok = (rel >= 0) & (rel + 1 < len(self._smoothed))
        idx = rel[ok]
        segment = self._smoothed_segment
        ok[ok] = segment[idx] == segment[idx + 1]
        idx = rel[ok]
        x0[ok], x1[ok] = self._smoothed[idx], self._smoothed[idx + 1]
        u[ok] = self.model.equivalent_input(x0[ok], x1[ok])
        return x0, x1, u, ok

    def steady_push(self, steps: int) -> tuple[Array, Array]:
        """The matched push over the last ``steps`` transitions: its mean and standard error.

        N per input, from the last :meth:`update` (zeros before a model). What a slope, a
        payload or a field the robot stands in pushes it with: the part of the equivalent
        input the commands do not explain, averaged.
        """
        zero = np.zeros(self.m)
        if self.model is None or self._smoothed is None or len(self._smoothed) < 2:
            return zero, zero
        segment = self._smoothed_segment
        x = self._smoothed
        same = np.flatnonzero(segment[1:] == segment[:-1])[-steps:]
        if len(same) < 2:
            return zero, zero
        push = self.model.equivalent_input(x[same], x[same + 1]) - self._acted[same]
        return push.mean(axis=0), push.std(axis=0, ddof=1) / math.sqrt(len(same))

    def last_push(self, y_next: Array) -> Array | None:
        """The matched push over the last recorded step, from the state measured after it.

        ŵ_k = Γ⁺ (x̄_{k+1} - Φ x̄_k - Σ_j Γ_j u_{k-j}), N per input: what moved the robot
        beyond what its forces and its state explain, steady push included (the model's
        constant column is not taken off). ``y_next`` in the leg coordinates of the last
        record. None before a model or a first record, and where the model's Γ may be off by
        its own size (:attr:`OneStepModel.gamma_error` ≥ 1: a push read through it could
        feed back on itself).
        """
        model = self.model
        if model is None or self.steps == 0 or not model.gamma_error < 1.0:
            return None
        last = self.steps - 1
        forces = np.array([self._u[(last - j) % self.memory] if last - j >= 0
                           else np.zeros(self.m) for j in range(model.gammas.shape[0])])
        forced = np.einsum('jnm,jm->n', model.gammas, forces)
        return model.equivalent_input(self._y[last % self.memory][None],
                                      np.asarray(y_next, dtype=float)[None], forced[None])[0]

    def pushes(self) -> tuple[Array, NDArray[np.int64]] | None:
        """The matched push of every kept transition within a segment, read as :meth:`last_push` reads.

        From the raw odometry through the current model (N per input, in time order), with
        each transition's step id; None where :meth:`last_push` would read none. What
        :meth:`PushCanceller.fit` learns to predict the next push from.
        """
        model = self.model
        if model is None or not model.gamma_error < 1.0:
            return None
        y, u, segment, first = self._ordered()
        same = np.flatnonzero(segment[1:] == segment[:-1])
        push = model.equivalent_input(y[same], y[same + 1], model.forced(u)[same])
        return push, same + first

    def push_noise(self, a: float) -> Array:
        """Standard deviation, from the odometry's noise alone, of :meth:`last_push` low-passed.

        N per input, for the filter y_k = y_{k-1} + a (ŵ_k - y_{k-1}) (:class:`PushCanceller`).
        ŵ's part from white measurement noise n (covariance R) is P (n_{k+1} - Φ n_k), P = Γ⁺;
        filtered, with b = 1 - a, it is a P (n_{k+1} + Σ_{j≥1} b^{j-1} (b I - Φ) n_{k+1-j}),
        of covariance a² P (R + (b I - Φ) R (b I - Φ)ᵀ / (1 - b²)) Pᵀ: the noise enters as
        a near-difference, which the filter largely cancels. Zeros with exact odometry or
        before a model.
        """
        if self.model is None or not self.noisy:
            return np.zeros(self.m)
        cached, variance = self._push_noise, self.variance.tobytes()
        if cached is None or not (cached[0] is self.model and cached[1] == a
                                  and cached[2] == variance):   # once per model
            cached = self._push_noise = (self.model, a, variance, self._push_noise_of(a))
        return cached[3].copy()

    def _push_noise_of(self, a: float) -> Array:
        assert self.model is not None
        R = np.diag(self.variance)
        P = np.linalg.pinv(self.model.gamma)
        b = 1.0 - a
        lead = b * np.eye(self.n) - self.model.phi
        cov = a * a * P @ (R + lead @ R @ lead.T / (1.0 - b * b)) @ P.T
        return np.sqrt(np.maximum(np.diag(cov), 0.0))

    def acted(self, steps: NDArray[np.int64], known: NDArray[np.bool_]) -> Array:
        """The commanded force that acted over each step (delayed as the model sees it).

        Γ⁺ Σ_j Γ_j u_{k-j}, where ``known`` (:meth:`estimates`' mask); the equivalent input
        less this is the matched push, ŵ (N): what a game against the disturbance learns
        from when the robot does not measure it.
        """
        out = np.zeros((len(steps), self.m))
        out[known] = self._acted[steps[known] - self._first]
        return out

    # ----------------------------------------------------------------- smoothing
    def _process_noise(self, model: OneStepModel, y: Array, u: Array,
                       segment: NDArray[np.int64]) -> Array:
        """Q = Γ Q_w Γᵀ: the disturbance, matched, as the smoother's process noise.

        Q_w (m x m) is the covariance of the equivalent input disturbance the measured
        states show, ŵ = Γ⁺ e with e their residuals under the model, less what the
        measurement noise puts into it (Γ⁺ (R + Φ R Φᵀ) Γ⁺ᵀ: e = n_{k+1} - Φ n_k + Γ w). A
        difference of two estimates: its eigenvalues are kept at least at the standard
        error of the first (√(2 / N) of its scale), below which Q_w cannot be told from
        zero. Positions get no noise of their own: a push moves them only through the
        velocities (a model that is exact but for the disturbance would need none; the
        floor leaves room for one that is not quite).
        """
        n = self.n
        same = segment[1:] == segment[:-1]
        same[:self.lags] = False
        e = (y[1:] - y[:-1] @ model.phi.T - model.forced(u)[:-1])[same]
        pinv = np.linalg.pinv(model.gamma)
        w = e @ pinv.T
        noise = self.read_noise(model)
        Qw = np.atleast_2d(np.cov(w.T)) - noise
        floor = math.sqrt(2.0 / max(len(w), 1)) * float(np.trace(noise + Qw)) / self.m
        vals, vecs = np.linalg.eigh(0.5 * (Qw + Qw.T))
        Qw = (vecs * np.maximum(vals, floor)) @ vecs.T
        G = model.gamma
        return np.asarray(G @ Qw @ G.T + 1e-12 * np.eye(n), dtype=float)

    def read_noise(self, model: OneStepModel | None = None) -> Array:
        """The covariance (m x m, N²) the odometry's noise puts into one read push.

        A read is Γ⁺ e with e = n_{k+1} - Φ n_k + Γ w: Γ⁺ (R + Φ R Φᵀ) Γ⁺ᵀ, R the
        measurement covariance (zeros with exact odometry). ``model``: by default the
        current one (zeros before a model).
        """
        model = self.model if model is None else model
        if model is None:
            return np.zeros((self.m, self.m))
        R = np.diag(self.variance)
        pinv = np.linalg.pinv(model.gamma)
        return np.asarray(pinv @ (R + model.phi @ R @ model.phi.T) @ pinv.T, dtype=float)

    def _smooth(self, model: OneStepModel, Q: Array, y: Array, u: Array,
                segment: NDArray[np.int64]) -> Array:
        """Rauch-Tung-Striebel smoothing of every segment with steady-state gains.

        Process noise Q (:meth:`_process_noise`), measurement noise the odometry's
        variances. Segments are smoothed side by side (one step of every segment per
        iteration; a segment is at most a horizon long).
        """
        n = self.n
        R = np.diag(np.maximum(self.variance, 1e-12))
        Pp = _predicted_covariance(model.phi, Q, R)
        K = Pp @ np.linalg.inv(Pp + R)
        Pf = (np.eye(n) - K) @ Pp
        C = Pf @ model.phi.T @ np.linalg.inv(Pp)
        count = len(y)
        drive = model.forced(u)
        starts = np.flatnonzero(np.r_[True, segment[1:] != segment[:-1]])
        ends = np.r_[starts[1:], count]
        longest = int((ends - starts).max())
        filtered = np.zeros_like(y)
        predicted = np.zeros_like(y)
        for k in range(longest):
            live = starts + k < ends
            i = starts[live] + k
            if k == 0:
                prior = y[i]
            else:
                prior = filtered[i - 1] @ model.phi.T + drive[i - 1]
            predicted[i] = prior
            filtered[i] = prior + (y[i] - prior) @ K.T
        smoothed = filtered.copy()
        for k in range(longest - 2, -1, -1):
            live = starts + k + 1 < ends
            i = starts[live] + k
            smoothed[i] = filtered[i] + (smoothed[i + 1] - predicted[i + 1]) @ C.T
        return smoothed


def _predicted_covariance(phi: Array, Q: Array, R: Array, steps: int = 1000) -> Array:
    """The steady predicted covariance of the Kalman filter of x' = Φx + w (Q), y = x + v (R).

    The discrete algebraic Riccati equation (scipy). Its Schur method fails on a model fitted
    to little motion, whose Φ is nearly defective ("reordering ... failed": seen on this
    controller's noisy, conveyed-robot test on one machine's LAPACK and not another's); the
    Riccati recursion from Q then gives the same covariance where it converges (the state
    is measured whole, so (Φ, I) is detectable and it does), and after ``steps`` steps
    otherwise, more than any segment the smoother runs over (at most a horizon).
    """
    try:
        solved = solve_discrete_are(phi.T, np.eye(phi.shape[0]), Q, R)
        if np.all(np.isfinite(solved)):
            return np.asarray(solved, dtype=float)
    except (ValueError, np.linalg.LinAlgError):
        pass
    P: Array = np.array(Q, dtype=float)
    for _ in range(steps):
        after = np.asarray(phi @ (P - P @ np.linalg.solve(P + R, P)) @ phi.T + Q, dtype=float)
        if np.allclose(after, P, rtol=1e-10, atol=1e-14):
            return after
        P = after
    return P


class PushCanceller:
    """Disturbance-observer feed-forward: the force that cancels the push the robot can expect.

    A first-order low-pass filter (time constant ``time``, s) of the per-step push
    :meth:`Observer.last_push`, the classic disturbance observer's Q filter, y_k. The
    feed-forward cancels not y_k itself but the best linear prediction from it of the push
    that the force commanded now will meet, ŵ = α + β y_k (:meth:`fit`: least squares of
    the push ``lead`` steps on, the model's actuation delay plus one, on y over the
    observer's memory; certainty equivalence: against the part of a push that cannot be
    predicted the policy is already the best one, and force spent on it is spent for
    nothing). A push slower than the filter (a slope, a payload, a field the robot stands
    in, a sinusoid of period well beyond 2π ``time``) gives β near 1 and is cancelled as
    integral action would cancel it; a white push gives β near 0 and only its mean α is
    cancelled. α and β are each kept only where they differ from zero at the two-sided
    rate ``false_alarm``, and β is kept within [0, 1] (below 0 the filter sees the
    odometry's noise, not a push; beyond 1 the loop would amplify). The estimate is made
    from the force that acted (the saturated one), so saturation does not wind it up.
    Under odometry noise y carries noise of its own (:meth:`Observer.push_noise`), and each
    component of the prediction is shrunk toward zero by z β times its standard deviation
    (soft threshold; z the two-sided normal quantile of ``false_alarm``). Before a first
    :meth:`fit` it predicts nothing (α = β = 0).
    """

    def __init__(self, m: int, dt: float, time: float, false_alarm: float) -> None:
        self.a = dt / (time + dt)
        """The filter's step weight."""
        self.estimate = np.zeros(m)
        """N per input: the filtered push y (unshrunk)."""
        self.alpha = np.zeros(m)
        """N per input: the mean of the push the prediction expects (:meth:`fit`)."""
        self.beta = np.zeros(m)
        """Per input: the weight of the filtered push in the prediction (:meth:`fit`)."""
        self._z = float(norm.ppf(1.0 - false_alarm / 2.0))

    def update(self, push: Array | None) -> None:
        """Take one step's push (N per input); None (no model to read it through): forget."""
        if push is None or not np.all(np.isfinite(push)):
            self.estimate = np.zeros_like(self.estimate)
            return
        self.estimate = self.estimate + self.a * (np.asarray(push, dtype=float) - self.estimate)

    def fit(self, reads: tuple[Array, NDArray[np.int64]] | None, lead: int) -> None:
        """α, β from the pushes read over the observer's memory (:meth:`Observer.pushes`).

        The reads are filtered in order as :meth:`update` filters them, and the read ``lead``
        steps after each filtered value is regressed on it (ordinary least squares with an
        intercept, per input), over the pairs whose steps are that far apart. None (no
        model) or too few pairs: α = β = 0.
        """
        m = len(self.alpha)
        self.alpha, self.beta = np.zeros(m), np.zeros(m)
        if reads is None:
            return
        push, steps = reads
        if len(push) < 3:
            return
        y = lfilter([self.a], [1.0, self.a - 1.0], push, axis=0)
        later = np.searchsorted(steps, steps + lead)
        pair = later < len(steps)
        pair[pair] = steps[later[pair]] == steps[pair] + lead
        if pair.sum() < 20:
            return
        x, target = y[pair], push[later[pair]]
        count = len(x)
        xm, tm = x.mean(axis=0), target.mean(axis=0)
        sxx = np.sum((x - xm) ** 2, axis=0)
        sxt = np.sum((x - xm) * (target - tm), axis=0)
        with np.errstate(divide='ignore', invalid='ignore'):
            beta = np.where(sxx > 0.0, sxt / sxx, 0.0)
            alpha = tm - beta * xm
            s2 = np.sum((target - alpha - beta * x) ** 2, axis=0) / max(count - 2, 1)
            se_beta = np.sqrt(s2 / sxx)
            se_alpha = np.sqrt(s2 * (1.0 / count + xm ** 2 / sxx))
        keep = np.isfinite(se_beta) & (np.abs(beta) > self._z * se_beta)
        beta = np.where(keep, np.clip(beta, 0.0, 1.0), 0.0)
        # α again for the β kept (β = 0: the mean and its standard error)
        alpha = tm - beta * xm
        se_alpha = np.where(keep, se_alpha, target.std(axis=0, ddof=1) / math.sqrt(count))
        alpha = np.where(np.abs(alpha) > self._z * se_alpha, alpha, 0.0)
        good = np.isfinite(alpha) & np.isfinite(beta)
        self.alpha, self.beta = np.where(good, alpha, 0.0), np.where(good, beta, 0.0)

    def prediction(self) -> Array:
        """N per input: the push expected over the step the next force acts, α + β y."""
        return np.asarray(self.alpha + self.beta * self.estimate, dtype=float)

    def force(self, noise: Array) -> Array:
        """The feed-forward force: minus the prediction shrunk by z β times ``noise`` (N, of y)."""
        allowance = self._z * self.beta * np.asarray(noise, dtype=float)
        predicted = self.prediction()
        shrunk = np.sign(predicted) * np.maximum(np.abs(predicted) - allowance, 0.0)
        return np.asarray(-shrunk, dtype=float)


def _with_the_p_before(ok: NDArray[np.bool_], p: int) -> NDArray[np.bool_]:
    """Where ``ok`` holds at a transition and at the ``p`` before it (those it has)."""
    out = np.asarray(ok, dtype=bool).copy()
    for i in range(1, p + 1):
        out[i:] &= ok[:-i]
    return out


def _largest_force(lagged: Array, m: int) -> Array:
    """N per input: the largest force of any lag in (some) rows of :func:`_lagged` forces."""
    return np.asarray(np.abs(lagged).max(axis=0).reshape(-1, m).max(axis=0), dtype=float)


def _friction_like(level: Array, error: Array, largest: Array) -> bool:
    """Whether identified Coulomb levels (N per input, with standard errors) can be friction.

    Friction dissipates: a level the data call negative at :data:`GAMMA_FALSE_ALARM`
    (one-sided, level + z SE < 0) is a force along the motion, what errors in variables
    make of odometry noise, not friction; at least one level must be called positive
    (level - z SE > 0); and none may exceed the largest force commanded in the transitions
    it was fitted on, which moved the robot (a friction beyond every force is a collinear
    column, not one the robot moved against).
    """
    z = _Z_ONE_SIDED
    return bool(np.all(level + z * error >= 0.0) and np.any(level - z * error > 0.0)
                and np.all(level <= largest))


def _weights(model: OneStepModel) -> Array:
    """W of a fit of x̄ on (x̄, lagged u, 1) that gives ``model`` (its Φ, Γ_j and constant)."""
    n = model.phi.shape[0]
    steady = np.zeros(n) if model.steady is None else model.steady
    return np.vstack([model.phi.T, model.gammas.transpose(0, 2, 1).reshape(-1, n), steady[None]])


def _lagged(u: Array, lags: int) -> Array:
    """(u_k, u_{k-1}, ..., u_{k-J}) for every k (zero before the first), (K, (J + 1) m)."""
    count = len(u)
    return np.hstack([np.vstack([np.zeros((min(j, count), u.shape[1])), u[:max(count - j, 0)]])
                      for j in range(lags + 1)])


def _gammas(w: Array, n: int, m: int, lags: int) -> Array:
    """(Γ_0, ..., Γ_J), (J + 1, n, m): the input columns of a fit ``w`` of x̄ on (x̄, lagged u, ...)."""
    return np.asarray(w[n:n + (lags + 1) * m].reshape(lags + 1, m, n).transpose(0, 2, 1), dtype=float)


def _gamma_error(regress: Array, target: Array, w: Array, n: int, m: int, lags: int) -> float:
    """:attr:`OneStepModel.gamma_error` of the fit ``w`` of ``target`` on ``regress``."""
    inverse, ridge_share = _ridge_inverse(regress)
    # Γ = Σ_j Γ_j: the sum over the lag columns of each input
    pick = np.zeros((len(w), m))
    for j in range(lags + 1):
        pick[n + j * m + np.arange(m), np.arange(m)] = 1.0
    with np.errstate(all='ignore'):      # a column that never moved: its scale is ~1e-300
        spread = np.diag(pick.T @ inverse @ pick)                      # per input
    dof = max(len(regress) - len(w), 1)
    sigma2 = np.sum((target - regress @ w) ** 2, axis=0) / dof      # per state component
    if not (np.all(np.isfinite(spread)) and np.all(np.isfinite(sigma2))):
        return math.inf
    se = math.sqrt(float(np.sum(np.outer(sigma2, spread))))
    gamma = (pick.T @ w).T
    smallest = float(np.linalg.svd(gamma, compute_uv=False).min()) if np.all(
        np.isfinite(gamma)) else 0.0
    z_value = float(norm.ppf(1.0 - GAMMA_FALSE_ALARM / 2.0))
    if smallest <= 0.0:
        return math.inf
    return z_value * se / smallest + ridge_share


def _ridge_inverse(regress: Array) -> tuple[Array, float]:
    """((ZᵀZ + ridge)⁻¹ in the columns' own units, the share the ridge takes of the weakest direction).

    Through standardised columns with :func:`_least_squares`' ridge, so a column the data
    leave undetermined (collinear with another, or one that never moved: its scale is
    ~1e-300) gets the variance of what the data do not say, not a singular matrix.
    """
    scale = np.sqrt(np.mean(regress ** 2, axis=0)) + 1e-300
    z = regress / scale
    ridge = RIDGE * len(z)
    eig, vec = np.linalg.eigh(z.T @ z)
    with np.errstate(all='ignore'):
        inverse = (vec / (np.maximum(eig, 0.0) + ridge)) @ vec.T / np.outer(scale, scale)
    return inverse, float(ridge / (max(eig.min(), 0.0) + ridge))


def _least_squares(regress: Array, target: Array, bias: Array | None = None,
                   states: int = 0) -> Array:
    """W of target ≈ regress W, columns standardised, a ridge of 1e-9 per standardised unit.

    ``bias`` (p x p): what noise in the regressors adds to ZᵀZ in expectation
    (:func:`_noise_bias`), taken off where what is left of the states' block (the first
    ``states`` columns) stays positive definite (where the states' noise is not larger
    than their motion: there the data cannot say more than the plain fit).
    """
    scale = np.sqrt(np.mean(regress ** 2, axis=0)) + 1e-300
    z = regress / scale
    gram = z.T @ z
    if bias is not None:
        # a column that never moved (scale ~1e-300, whose square underflows to 0) has no
        # noise to take off: 0 / 0 there, and the correction is left out where it is not finite
        with np.errstate(all='ignore'):
            corrected = gram - bias / np.outer(scale, scale)
        block = corrected[:states, :states]
        if (states and np.all(np.isfinite(corrected))
                and np.all(np.linalg.eigvalsh(0.5 * (block + block.T)) > 0.0)):
            gram = corrected
    w = np.linalg.solve(gram + RIDGE * len(z) * np.eye(len(gram)), z.T @ target)
    return np.asarray(w / scale[:, None], dtype=float)


def _noise_bias(variance: Array, sensitivity: Array, width: int) -> Array:
    """(p x p): E[ZᵀZ] - E[ZᵀZ_true] as it enters the normal equations, for white odometry noise.

    The regressors z_k = (y_k, u_k, ..., u_{k-J}, 1) hold the measured state y_k = x_k + n_k
    (n white, covariance Σ = diag(``variance``)), and the force u_k followed it by ∂u/∂y =
    S_k (``sensitivity``, one per transition fitted): z_k = z*_k + M_k n_k with
    M_k = (I; S_k; 0). The target y_{k+1} = Φ y_k + Σ_j Γ_j u_{k-j} - Φ n_k + ... carries
    -Φ n_k, so E[Zᵀ Y] = (ZᵀZ - A Eᵀ) W with A = Σ_k M_k Σ and E the states' columns:
    least squares on ZᵀZ - A Eᵀ is consistent (corrected least squares, Fuller 1987, ch. 2;
    the feedback term because a state feedback of noisy odometry moves the force with the
    noise). Plain least squares attenuates Φ toward 0 and biases Γ: on a rover with
    σ_v = 0.05 m/s fed back through a time-varying gain and a 2-step delay, 4 N of probing,
    Φ_vv 0.88-0.91 against 0.945 and Γ 0.89-1.36 of the plant's; corrected, Φ_vv
    0.940-0.950 and Γ 0.89-1.06 (``test_observer.py`` checks it on a PD-held rover).
    """
    n = len(variance)
    m = sensitivity.shape[1] if sensitivity.ndim == 3 else 0
    sigma = np.diag(variance)
    A = np.zeros((width, n))
    A[:n] = len(sensitivity) * sigma
    if m:
        A[n:n + m] = sensitivity.sum(axis=0) @ sigma
    bias = np.zeros((width, width))
    bias[:, :n] = A
    return bias


def _cochrane_orcutt(regress: Array, target: Array, usable: NDArray[np.bool_], p: int,
                     a: Array) -> tuple[Array, Array, float]:
    """(W, AR coefficients, -2 log-likelihood per transition) of :data:`AR_ITERATIONS` from ``a``.

    The likelihood is Gaussian with a variance of its own per state component (the
    innovations of the last W and AR coefficients): scale-free, so positions and
    velocities weigh alike; inf where the fit is not finite.
    """
    for _ in range(AR_ITERATIONS if p else 1):
        w = _least_squares(_ar_filter(regress, a)[usable], _ar_filter(target, a)[usable])
        if not p:
            break
        a = _ar_coefficients(target - regress @ w, usable, p)
    innovations = _ar_filter(target - regress @ w, a)[usable]
    power = np.mean(innovations ** 2, axis=0)
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(power))):
        return w, a, math.inf
    return w, a, float(np.sum(np.log(np.maximum(power, 1e-300))))


def _ar_filter(z: Array, a: Array) -> Array:
    """z_k - Σ_i a_i z_{k-i} (the first rows are dropped by the caller's mask)."""
    out = z.copy()
    for i, ai in enumerate(a, start=1):
        out[i:] -= ai * z[:-i]
    return out


def _ar_coefficients(e: Array, usable: NDArray[np.bool_], p: int) -> Array:
    """The AR coefficients of e_k = Σ a_i e_{k-i} + ε_k, pooled over the components (unit spread each)."""
    spread = e[usable].std(axis=0)
    moving = spread > 0.0              # a component the model fits exactly carries no AR
    if not moving.any():
        return np.zeros(p)
    r = e[:, moving] / spread[moving]
    lags = np.stack([np.vstack([np.zeros((i, r.shape[1])), r[:-i]]) for i in range(1, p + 1)],
                    axis=-1)[usable]
    gram = np.einsum('kip,kiq->pq', lags, lags)
    rhs = np.einsum('kip,ki->p', lags, r[usable])
    if not (np.all(np.isfinite(gram)) and np.all(np.isfinite(rhs))):
        return np.zeros(p)
    try:
        a = np.linalg.solve(gram + 1e-9 * np.eye(p), rhs)
    except np.linalg.LinAlgError:
        # residuals of a wild fit (a unit-root filter from a warm start, seen on the MuJoCo
        # plant at mu = 0.3) made the lags collinear, and the controller node failed
        a = np.linalg.lstsq(gram + 1e-9 * np.eye(p), rhs, rcond=None)[0]
    return np.asarray(a, dtype=float) if np.all(np.isfinite(a)) else np.zeros(p)


def _invertible(gamma: Array) -> bool:
    """Whether Γ has full column rank, numerically (every force direction moves the robot)."""
    if not np.all(np.isfinite(gamma)):
        return False
    s = np.linalg.svd(gamma, compute_uv=False)
    return bool(s.min() > 1e-6 * s.max())
