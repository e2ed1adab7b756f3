"""The LQ-optimal feed-forward of a push the robot can predict (no rclpy, no ROS).

The observer (:mod:`rrtq_controller.observer`) identifies the robot's one-step model
x_{k+1} = Φ x_k + Γ u_k + e_k; the matched push over each step, w_k = Γ⁺ e_k (N per input),
is read from the odometry (:meth:`Observer.last_push`). Model it as the output of an
internal model with state ω,

    ω_{k+1} = A_ω ω_k (+ innovations),    w_k = G ω_k (+ what is not predictable),

ω = (c, h) per input: a constant c (a slope, a payload, a field the robot stands in: A = 1)
plus, where the reads show one, a harmonic h of the frequency they show (a rotation by ω₀Δt
per step; :func:`find_harmonic`). For the discrete LQ cost Σ (xᵀ M x + uᵀ R u) Δt with the
policy's feedback u = -K x, the optimal control with ω known is

    u = -K x - K_ω ω,   K_ω = H⁻¹ Γᵀ (P Γ G + S A_ω),   H = R Δt + Γᵀ P Γ,

S = (Φ - Γ K)ᵀ (P Γ G + S A_ω) (a Sylvester equation; P, K the discrete Riccati solution):
certainty equivalence, the disturbance's own dynamics taken into account. For a steady push
on a plant without a spring it is the whole push (K_ω G = I on c: the robot holds its target,
as integral action would), for a periodic one much less than the push: against a 0.1 Hz
sinusoid on the 40 kg rover it halves the cost the feedback alone pays, where cancelling the
whole push costs a quarter more than the feedback alone (``test_lq_feedforward.py``).

Why a harmonic and not the observer's AR model of the residual: under odometry noise a read
carries ~50 N RMS of noise (σ_v = 0.05 m/s on 40 kg at Δt = 0.05 s) against a 20 N push, and
an AR fit to noisy reads is biased toward white (errors in variables: a 0.1 Hz sinusoid read
as AR (0.78, 0.17) instead of (2.0, -1.0)), so nothing of it was predicted; the periodogram
of the same reads finds the frequency to its resolution with a false-alarm probability below
10⁻⁸ (docs/observer.md §7).

The ω the gain multiplies starts at each fit from the least-squares fit of the constant and
the harmonic over the observer's memory and is then tracked by a steady-state Kalman filter
on the reads (:class:`PushFeedforward`): the reads' noise is the odometry's
(:meth:`Observer.read_noise`) plus the push's unpredictable part (the fit's residual less that
noise), so that a white push and odometry noise feed nothing forward; it is predicted 1 + d
steps on (d the identified delay: the force commanded now acts then).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solve_discrete_are
from scipy.ndimage import median_filter
from scipy.stats import gamma as gamma_distribution
from scipy.stats import norm

Array = NDArray[np.float64]

__all__ = ['find_harmonic', 'internal_model', 'feedforward_gain', 'PushFeedforward']

CONSTANT_TIME = 1.0
"""s: τ, the time in which the constant follows a change of the push. Its random walk per
step is (Δt / τ)² of the variance of the push's unpredictable part, so that the steady-state filter
(gain ≈ √ of this share) follows a change of the push (a field entered) within about τ and
averages about τ / Δt reads (20 at Δt = 0.05 s). The first version took a share of 1 (the constant an average of
two reads): its posterior standard deviation was then of the order of the unpredictable
part, and the soft threshold (z = 2.58 of it) held back a push below that — on the MuJoCo
plant at μ = 0.02 the robot stopped 0.3–0.6 m short of each waypoint, its
2–6 N of feedback below the 8 N of friction, and no seed of five reached the goal (at this
share seed 0 got about twice as far in 300 s, and still not there). At this share the
rover holding station under a steady push is 0.08 m off (0.21 m at 1) with odometry noise,
and nothing of a white push is fed forward (0.29 N RMS at 1;
``test_lq_feedforward.py``)."""

MIN_CYCLES = 4
"""A harmonic is looked for from frequencies with this many cycles in each half of the reads
on (a slower change is the constant's to follow)."""


CONTINUUM_BINS = 32
"""Fourier bins of the running median the periodogram is normalized by: a line is judged
against the local continuum of the reads' spectrum, not against white noise. A read's noise
is Γ⁺ (n_{k+1} - Φ n_k), a difference of the odometry's noise: its spectrum rises toward
the Nyquist frequency, and against its mean a white-noise test found "harmonics" there in
pure noise (through a poor first model, fed forward as ±30 N on a robot that held no push)."""


def _periodogram(push: Array, steps: NDArray[np.int64]) -> tuple[Array, Array, int]:
    """The periodogram of reads at integer step ids (gaps allowed: zero-filled after the mean).

    Returns the frequencies (cycles per step), the m inputs' normalized power summed and the
    number of independent frequencies. Each input's power is divided by its local continuum
    (the running median over ``CONTINUUM_BINS`` Fourier bins, over ln 2, the median of
    Exp(1)): under reads whose spectrum is smooth (white, or odometry noise through the
    model) each input's normalized power at a Fourier frequency is about Exp(1), the sum
    Gamma(m, 1).
    """
    span = int(steps[-1] - steps[0]) + 1
    pad = 4
    size = 1 << int(math.ceil(math.log2(pad * span)))        # zero-padded four times
    grid = np.zeros((size, push.shape[1]))
    grid[steps - steps[0]] = push - push.mean(axis=0)
    power = np.square(np.abs(np.fft.rfft(grid, axis=0)))
    freqs = np.asarray(np.fft.rfftfreq(size), dtype=float)
    window = CONTINUUM_BINS * size // span | 1
    # mirrored at both ends: the spectrum of real reads is symmetric about 0 and 1/2
    continuum = median_filter(power, size=(window, 1), mode='mirror') / math.log(2.0)
    used = np.all(continuum > 0.0, axis=0)
    total = (power[:, used] / continuum[:, used]).sum(axis=1)
    # from MIN_CYCLES in the window on, and as far from the Nyquist frequency, where a real
    # signal's coefficients are nearly real (their power χ²₁, not exponential)
    keep = (freqs >= MIN_CYCLES / span) & (freqs <= 0.5 - MIN_CYCLES / span)
    return freqs[keep], total[keep], max(int(0.5 * span) - 2 * MIN_CYCLES, 1)


def find_harmonic(push: Array, steps: NDArray[np.int64], false_alarm: float) -> float | None:
    """The frequency (rad per step) of a harmonic the reads carry throughout, or None.

    The periodogram's peak (:func:`_periodogram`) must be significant at ``false_alarm`` in
    each half of the reads (the probability that the largest of the independent frequencies'
    normalized powers exceeds it under a smooth spectrum: 1 - (1 - Gamma_sf(P; m))^M), and
    the halves' peaks must agree to two of their frequency bins: a push that persists, not a
    transient (a field crossed once) whose power lies at low frequencies too. Each half
    must span well more than the continuum's window (``16 CONTINUUM_BINS`` reads in all).
    """
    if len(push) < 16 * CONTINUUM_BINS:
        return None
    peaks = []
    half = len(push) // 2
    for part in (slice(0, half), slice(half, len(push))):
        freqs, power, independent = _periodogram(push[part], steps[part])
        if len(freqs) == 0:
            return None
        k = int(np.argmax(power))
        chance = -math.expm1(independent * math.log1p(
            -min(float(gamma_distribution.sf(power[k], push.shape[1])), 1.0 - 1e-16)))
        if chance >= false_alarm:
            return None
        peaks.append((float(freqs[k]), int(steps[part][-1] - steps[part][0]) + 1))
    (f1, span1), (f2, span2) = peaks
    if abs(f1 - f2) > 2.0 / min(span1, span2):
        return None
    freqs, power, _ = _periodogram(push, steps)               # the whole memory: the finest
    return 2.0 * math.pi * float(freqs[int(np.argmax(power))])


def internal_model(omega: float | None, m: int, decay: float = 1.0) -> tuple[Array, Array]:
    """(A_ω, G) of the push's internal model for m inputs and a harmonic of ``omega``.

    ``omega`` in rad per step; None: the constant alone. ω = (c, h) with c m wide and h two
    per input (its rotation by ω per step; the push is c + the first of each pair).
    ``decay`` (< 1) damps the whole model: the tests compare with a Riccati problem that
    needs a stabilisable augmented plant.
    """
    q = m if omega is None else 3 * m
    A = np.zeros((q, q))
    A[:m, :m] = decay * np.eye(m)
    G = np.zeros((m, q))
    G[:, :m] = np.eye(m)
    if omega is not None:
        c, s = math.cos(omega), math.sin(omega)
        for j in range(m):
            i = m + 2 * j
            A[i:i + 2, i:i + 2] = decay * np.array([[c, -s], [s, c]])
            G[j, i] = 1.0
    return A, G


def feedforward_gain(phi: Array, gamma: Array, M: Array, R: Array, dt: float, A: Array,
                     G: Array) -> Array:
    """K_ω (m x q) of the module doc, for the model (Φ, Γ) and the weights M, R (per second).

    Raises ``np.linalg.LinAlgError`` where the Riccati or Sylvester equation has no solution.
    """
    n, q = phi.shape[0], A.shape[0]
    Rd = np.asarray(R, dtype=float) * dt
    P = solve_discrete_are(phi, gamma, np.asarray(M, dtype=float) * dt, Rd)
    H = Rd + gamma.T @ P @ gamma
    K = np.linalg.solve(H, gamma.T @ P @ phi)
    closed = phi - gamma @ K
    # S - closedᵀ S A = closedᵀ P Γ G, column-major vec: (I - Aᵀ ⊗ closedᵀ) vec S
    rhs = closed.T @ P @ gamma @ G
    S = np.linalg.solve(np.eye(n * q) - np.kron(A.T, closed.T),
                        rhs.reshape(-1, order='F')).reshape(n, q, order='F')
    return np.asarray(np.linalg.solve(H, gamma.T @ (P @ gamma @ G + S @ A)), dtype=float)


def _kalman_gain(A: Array, G: Array, Q: Array, R_v: Array,
                 steps: int = 2000) -> tuple[Array, Array]:
    """The steady-state Kalman gain and posterior covariance of ω_{k+1} = A ω_k + ε, r_k = G ω_k + v.

    By scipy's Schur-based solver, else by iterating the Riccati recursion: a unit root with
    a nearly exact read can be too ill-conditioned for the solver (it failed on the reads of
    a steady push), not for the recursion.
    """
    try:        # the predicted covariance by a Schur-based solver where it can
        Pp = solve_discrete_are(A.T, G.T, Q, R_v)
        if np.all(np.isfinite(Pp)):
            gain = Pp @ G.T @ np.linalg.inv(G @ Pp @ G.T + R_v)
            return gain, Pp - gain @ G @ Pp
    except (np.linalg.LinAlgError, ValueError):
        pass
    P = Q.copy()
    gain = np.zeros((A.shape[0], G.shape[0]))
    for _ in range(steps):
        P = A @ P @ A.T + Q
        last, gain = gain, P @ G.T @ np.linalg.inv(G @ P @ G.T + R_v)
        P = P - gain @ G @ P
        P = 0.5 * (P + P.T)
        if np.abs(gain - last).max() < 1e-12:
            break
    return gain, P


class PushFeedforward:
    """The force -K_ω ω̂ that meets the push the robot can predict (module doc).

    :meth:`fit` at each identification (the model, the reads over the observer's
    memory); :meth:`update` with each step's read; :meth:`force` the
    feed-forward for the force commanded now. Before a fit, or without a model to read
    pushes through (``update(None)``), it feeds nothing forward and forgets its estimate.
    """

    def __init__(self, m: int, dt: float, M: Array, R: Array, false_alarm: float) -> None:
        self.m, self.dt = m, dt
        self.false_alarm = false_alarm
        self._z = float(norm.ppf(1.0 - false_alarm / 2.0))
        self.constant_std = np.zeros(m)
        """N per input: the posterior standard deviation of the constant c."""
        self.M, self.R = np.asarray(M, dtype=float), np.asarray(R, dtype=float)
        self.A: Array | None = None
        self.G = np.zeros((m, 0))
        self.gain = np.zeros((m, 0))
        """K_ω (m x q), N per unit of ω."""
        self.kalman = np.zeros((0, m))
        self.ahead = np.zeros((0, 0))
        """A_ω to the power ``lead`` (:meth:`fit`): ω̂ carried to the step the force acts."""
        self.state = np.zeros(0)
        """ω̂ after the last read."""

    def fit(self, phi: Array, gamma: Array, reads: tuple[Array, NDArray[np.int64]] | None,
            read_noise: Array, lead: int) -> None:
        """The internal model, its Kalman gain, K_ω and ω̂ from the observer's current model.

        ``reads``: the pushes read over the memory (:meth:`Observer.pushes`), N per input,
        with their step ids; ``read_noise``: the covariance (m x m) odometry noise puts into
        one read; ``lead``: steps from the last read to the step the next force acts (the
        delay plus one). Nothing is fed forward where the reads are too few, or where the
        equations have no solution (a model with no stabilising feedback).
        """
        m = self.m
        self.A, self.gain = None, np.zeros((m, 0))
        if reads is None or len(reads[0]) < 16 * MIN_CYCLES:
            return
        push, steps = np.asarray(reads[0], dtype=float), np.asarray(reads[1])
        omega = find_harmonic(push, steps, self.false_alarm)
        A, G = internal_model(omega, m)
        q = A.shape[0]
        # the constant and the harmonic by least squares over the memory; what is left, less
        # the odometry's noise, is the push's unpredictable part
        k = steps.astype(float)
        columns = [np.ones_like(k)]
        if omega is not None:
            columns += [np.cos(omega * k), np.sin(omega * k)]
        basis = np.column_stack(columns)
        coef = np.linalg.lstsq(basis, push, rcond=None)[0]
        left = push - basis @ coef
        noise = np.asarray(read_noise, dtype=float)
        scale = max(float(np.trace(np.atleast_2d(np.cov(push.T)))) / m, 1e-12)
        unpredictable = np.atleast_2d(np.cov(left.T)) - noise
        vals, vecs = np.linalg.eigh(0.5 * (unpredictable + unpredictable.T))
        unpredictable = (vecs * np.maximum(vals, 1e-6 * scale)) @ vecs.T
        Q = np.zeros((q, q))
        Q[:m, :m] = (self.dt / CONSTANT_TIME) ** 2 * unpredictable
        state = np.zeros(q)
        state[:m] = coef[0]
        if omega is not None:
            # the harmonic wanders by its amplitude times the frequency's resolution per step
            resolution = 2.0 * math.pi / (steps[-1] - steps[0] + 1)
            last = omega * float(steps[-1])
            for j in range(m):
                a, b = coef[1, j], coef[2, j]
                i = m + 2 * j
                Q[i:i + 2, i:i + 2] = ((a * a + b * b) * resolution ** 2 + 1e-6 * scale) * np.eye(2)
                state[i:i + 2] = (a * math.cos(last) + b * math.sin(last),
                                  a * math.sin(last) - b * math.cos(last))
        R_v = noise + unpredictable + 1e-6 * scale * np.eye(m)
        try:
            kalman, posterior = _kalman_gain(A, G, Q, R_v)
            gain = feedforward_gain(phi, gamma, self.M, self.R, self.dt, A, G)
        except (np.linalg.LinAlgError, ValueError):
            return
        if not (np.all(np.isfinite(kalman)) and np.all(np.isfinite(gain))):
            return
        self.kalman = kalman
        self.constant_std = np.sqrt(np.maximum(np.diag(posterior)[:m], 0.0))
        self.A, self.G, self.gain = A, G, gain
        self.ahead = np.linalg.matrix_power(A, max(int(lead), 1))
        self.state = state

    def update(self, push: Array | None) -> None:
        """Take one step's read (N per input); None (no model to read it through): forget."""
        if push is None or not np.all(np.isfinite(push)) or self.A is None:
            self.state = np.zeros(0 if self.A is None else self.A.shape[0])
            return
        predicted = self.A @ self.state
        self.state = predicted + self.kalman @ (np.asarray(push, dtype=float) - self.G @ predicted)

    def force(self) -> Array:
        """N per input: -K_ω ω̂ predicted ``lead`` steps on (zeros before a fit).

        The constant is first shrunk toward zero by z times its posterior standard deviation.
        """
        if self.A is None:          # fit sets A and a state of its size together
            return np.zeros(self.m)
        state = self.state.copy()
        c = state[:self.m]
        state[:self.m] = np.sign(c) * np.maximum(np.abs(c) - self._z * self.constant_std, 0.0)
        return np.asarray(-self.gain @ (self.ahead @ state), dtype=float)
