"""The LQ-optimal feed-forward of a push the robot can predict (no rclpy, no ROS).

The observer (:mod:`rrtq_controller.observer`) identifies the robot's one-step model
x_{k+1} = Φ x_k + Γ u_k + e_k and the disturbance's AR(p) model; the matched push over each
step, w_k = Γ⁺ e_k (N per input), is read from the odometry (:meth:`Observer.last_push`).
Model it as the output of an internal model with state ω,

    ω_{k+1} = A_ω ω_k (+ innovations),    w_k = G ω_k,

ω = (c, w_k, w_{k-1}, ..., w_{k-p+1}) per input: a constant c (a slope, a payload, a field
the robot stands in: A = 1) plus the AR(p) part (a sinusoid is AR(2) with a unit root, a
white push has no predictable part). For the discrete LQ cost Σ (xᵀ M x + uᵀ R u) Δt with
the policy's feedback u = -K x, the optimal control with ω known is

    u = -K x - K_ω ω,   K_ω = H⁻¹ Γᵀ (P Γ G + S A_ω),   H = R Δt + Γᵀ P Γ,

S = (Φ - Γ K)ᵀ (P Γ G + S A_ω) (a Sylvester equation; P, K the discrete Riccati solution):
certainty equivalence, the disturbance's own dynamics taken into account. For a steady push
on a plant without a spring it is the whole push (K_ω G = I on c: the robot holds its target,
as integral action would), for a periodic one much less than the push: against a 0.1 Hz
sinusoid on the 40 kg rover it halves the cost the feedback alone pays, where cancelling the
whole push costs a quarter more than the feedback alone (``test_push_feedforward.py``).

The ω the gain multiplies is estimated by a steady-state Kalman filter on the reads
(:class:`PushFeedforward`): the innovations' covariance from the reads' own AR residuals
(less what the odometry's noise puts into them), the reads' noise from the odometry's
(:meth:`Observer.read_noise`), so that a white push (no predictable part) and odometry
noise feed nothing forward, and predicted 1 + d steps on (d the identified delay: the force
commanded now acts then).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solve_discrete_are
from scipy.stats import norm

Array = NDArray[np.float64]

__all__ = ['internal_model', 'feedforward_gain', 'PushFeedforward']

CONSTANT_WALK = 1.0
"""The constant's random walk per step, as a share of the AR innovations' variance. Smaller,
the constant is told apart from a persistent AR part more slowly: on the rover held at its
target against a steady 20 N push it was still 0.43 m short after 50 s at 1/20 (the reads'
AR(2), fitted to a residual that is rounding noise, took the push for a slow oscillation),
0.05 m at 1, 2 mm at 5; under a white push the constant is then an average of a few reads,
soft-thresholded by z times its posterior standard deviation (0.3 N RMS fed forward against
a 20 N RMS push at 1, 0.55 N at 5; ``test_lq_feedforward.py``)."""


def internal_model(ar: Array, m: int) -> tuple[Array, Array]:
    """(A_ω, G) of the push's internal model for AR coefficients ``ar`` and m inputs.

    ω = (c, w_k, ..., w_{k-p+1}), each block m wide; w_k + c is the push (G).
    """
    p = len(ar)
    q = (p + 1) * m
    A = np.zeros((q, q))
    A[:m, :m] = np.eye(m)
    for i, a in enumerate(ar):
        A[m:2 * m, (1 + i) * m:(2 + i) * m] = a * np.eye(m)
    for i in range(1, p):
        A[(1 + i) * m:(2 + i) * m, i * m:(1 + i) * m] = np.eye(m)
    G = np.zeros((m, q))
    G[:, :m] = np.eye(m)
    if p:
        G[:, m:2 * m] = np.eye(m)
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

    :meth:`fit` at each identification (the model, its AR coefficients, the reads over the
    observer's memory); :meth:`update` with each step's read; :meth:`force` the
    feed-forward for the force commanded now. Before a fit, or without a model to read
    pushes through (``update(None)``), it feeds nothing forward and forgets its estimate.
    """

    def __init__(self, m: int, dt: float, M: Array, R: Array, false_alarm: float) -> None:
        self.m, self.dt = m, dt
        self._z = float(norm.ppf(1.0 - false_alarm / 2.0))
        self.constant_std = np.zeros(m)
        """N per input: the posterior standard deviation of the constant c."""
        self.M, self.R = np.asarray(M, dtype=float), np.asarray(R, dtype=float)
        self.A: Array | None = None
        self.G = np.zeros((m, 0))
        self.gain = np.zeros((m, 0))
        """K_ω (m x q), N per unit of ω."""
        self.kalman = np.zeros((0, m))
        self.lead = 1
        self.state = np.zeros(0)
        """ω̂ after the last read."""

    def fit(self, phi: Array, gamma: Array, ar: Array,
            reads: tuple[Array, NDArray[np.int64]] | None, read_noise: Array, lead: int) -> None:
        """The internal model, its Kalman gain and K_ω from the observer's current model.

        ``reads``: the pushes read over the memory (:meth:`Observer.pushes`), N per input,
        with their step ids; ``read_noise``: the covariance (m x m) odometry noise puts into
        one read; ``lead``: steps from the last read to the step the next force acts (the
        delay plus one). Nothing is fed forward where the reads are too few, or where the
        equations have no solution (a model with no stabilising feedback).
        """
        m = self.m
        self.A, self.gain = None, np.zeros((m, 0))
        if reads is None or len(reads[0]) < 20 * (len(ar) + 2):
            return
        push, steps = reads
        A, G = internal_model(np.asarray(ar, dtype=float), m)
        q = A.shape[0]
        # the AR part's innovations from consecutive reads, less the noise the reads carry
        p = len(ar)
        w = push - push.mean(axis=0)
        ok = np.ones(len(w), dtype=bool)
        ok[:p] = False
        for i in range(1, p + 1):
            ok[i:] &= steps[i:] == steps[:-i] + i
        innovation = w.copy()
        for i, a in enumerate(ar, start=1):
            innovation[i:] -= a * w[:-i]
        if ok.sum() < 10:
            return
        noise = np.asarray(read_noise, dtype=float) * (1.0 + float(np.sum(np.square(ar))))
        Q_e = np.atleast_2d(np.cov(innovation[ok].T)) - noise
        vals, vecs = np.linalg.eigh(0.5 * (Q_e + Q_e.T))
        scale = max(float(np.trace(np.atleast_2d(np.cov(innovation[ok].T)))) / m, 1e-12)
        Q_e = (vecs * np.maximum(vals, 1e-6 * scale)) @ vecs.T
        Q = np.zeros((q, q))
        Q[:m, :m] = CONSTANT_WALK * Q_e
        if p:
            Q[m:2 * m, m:2 * m] = Q_e
        R_v = np.asarray(read_noise, dtype=float) + 1e-6 * scale * np.eye(m)
        try:
            kalman, posterior = _kalman_gain(A, G, Q, R_v)
            gain = feedforward_gain(phi, gamma, self.M, self.R, self.dt, A, G)
        except (np.linalg.LinAlgError, ValueError):
            return
        if not (np.all(np.isfinite(kalman)) and np.all(np.isfinite(gain))):
            return
        self.kalman = kalman
        self.constant_std = np.sqrt(np.maximum(np.diag(posterior)[:m], 0.0))
        self.A, self.G, self.gain, self.lead = A, G, gain, max(int(lead), 1)
        if self.state.shape != (q,):
            self.state = np.zeros(q)

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
        if self.A is None or self.state.shape != (self.A.shape[0],):
            return np.zeros(self.m)
        state = self.state.copy()
        c = state[:self.m]
        state[:self.m] = np.sign(c) * np.maximum(np.abs(c) - self._z * self.constant_std, 0.0)
        ahead = np.linalg.matrix_power(self.A, self.lead) @ state
        return np.asarray(-self.gain @ ahead, dtype=float)
