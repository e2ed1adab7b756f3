"""Finite-horizon (game) Riccati equation, integrated in time-to-go.

The ground truth the model-free controller is tested against, and the source of the
worst-case disturbance.  With time-to-go ``tau = T - t`` the backward equation of the
robust paper (eq. 8)

    -dP/dt = A^T P + P A + M + gamma^-2 P F F^T P - P B R^-1 B^T P,   P(T) = P_T

becomes an initial value problem in ``tau`` with ``P(tau = 0) = P_T``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.integrate import solve_ivp

__all__ = ['RiccatiEscape', 'RiccatiSolution', 'solve_riccati', 'game_gamma_bound']


class RiccatiEscape(ArithmeticError):
    """The Riccati solution has a finite escape within the horizon.

    Attributes
    ----------
    tau : float
        Time-to-go at which the solution was declared unbounded, s.
    """

    def __init__(self, message: str, tau: float) -> None:
        super().__init__(message)
        self.tau = tau


def _as_matrix(name: str, value: npt.ArrayLike, shape: tuple[int, int]) -> np.ndarray:
    mat = np.array(value, dtype=float, ndmin=2)
    if mat.shape != shape:
        raise ValueError(f'{name} must have shape {shape}, got {mat.shape}')
    if not np.all(np.isfinite(mat)):
        raise ValueError(f'{name} must be finite')
    return mat


class RiccatiSolution:
    """Dense solution ``P(tau)`` of the (game) Riccati equation on ``tau in [0, T]``.

    Not constructed directly: see :func:`solve_riccati`.
    """

    def __init__(
        self,
        sol: object,
        n: int,
        T: float,
        B: np.ndarray,
        R: np.ndarray,
        F: np.ndarray | None,
        gamma: float | None,
    ) -> None:
        self._sol = sol
        self._n = n
        self._T = T
        self._B = B
        self._R = R
        self._F = F
        self._gamma = gamma

    @property
    def T(self) -> float:
        """Horizon, s."""
        return self._T

    @property
    def n(self) -> int:
        """State dimension."""
        return self._n

    @property
    def F(self) -> np.ndarray | None:
        """Disturbance matrix of the game, or None for plain LQR."""
        return self._F

    @property
    def gamma(self) -> float | None:
        """Attenuation level of the game, or None for plain LQR."""
        return self._gamma

    def P(self, tau: float) -> np.ndarray:
        """Return the symmetric P at time-to-go ``tau`` (clipped to [0, T]), shape (n, n)."""
        t = min(max(float(tau), 0.0), self._T)
        y = self._sol(t)  # type: ignore[operator]
        p = np.asarray(y, dtype=float).reshape(self._n, self._n)
        return 0.5 * (p + p.T)

    __call__ = P

    def gain(self, tau: float) -> np.ndarray:
        """Optimal gain ``K = R^-1 B^T P(tau)``, shape (m, n): ``u* = -K x_bar`` (eq. 9)."""
        return np.linalg.solve(self._R, self._B.T @ self.P(tau))

    def disturbance_gain(self, tau: float) -> np.ndarray:
        """Worst-case gain ``L = gamma^-2 F^T P(tau)``, shape (q, n): ``d* = L x_bar`` (eq. 10)."""
        if self._F is None or self._gamma is None:
            raise ValueError('disturbance_gain needs a game solution (F and gamma)')
        return self._F.T @ self.P(tau) / self._gamma**2


def solve_riccati(
    A: npt.ArrayLike,
    B: npt.ArrayLike,
    M: npt.ArrayLike,
    R: npt.ArrayLike,
    P_T: npt.ArrayLike,
    T: float,
    F: npt.ArrayLike | None = None,
    gamma: float | None = None,
    *,
    escape_norm: float = 1e8,
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> RiccatiSolution:
    """Integrate the finite-horizon (game) Riccati equation in time-to-go.

    Parameters
    ----------
    A, B : array_like
        Plant matrices, shapes (n, n) and (n, m).
    M : array_like, shape (n, n)
        State weight (symmetric, >= 0).
    R : array_like, shape (m, m)
        Control weight (symmetric, > 0).
    P_T : array_like, shape (n, n)
        Terminal weight, the initial condition at ``tau = 0``.
    T : float
        Horizon, s (> 0).
    F : array_like, shape (n, q), optional
        Disturbance matrix; with ``gamma`` adds the game term ``gamma^-2 P F F^T P``.
    gamma : float, optional
        Attenuation level (> 0).
    escape_norm : float
        ``P`` is declared unbounded once its largest entry exceeds ``escape_norm``
        times ``max(1, |P_T|, |M| T)`` (the scale a bounded solution can reach).
    rtol, atol : float
        Integrator tolerances (``atol`` is scaled like ``escape_norm``).

    Returns
    -------
    RiccatiSolution

    Raises
    ------
    RiccatiEscape
        If the solution blows up (finite escape) within ``[0, T]``.
    """
    a = np.array(A, dtype=float, ndmin=2)
    n = a.shape[0]
    a = _as_matrix('A', a, (n, n))
    b = np.array(B, dtype=float, ndmin=2)
    b = _as_matrix('B', b, (n, b.shape[1] if b.ndim == 2 else -1))
    m = b.shape[1]
    mm = _as_matrix('M', M, (n, n))
    r = _as_matrix('R', R, (m, m))
    p_t = _as_matrix('P_T', P_T, (n, n))
    if not (math.isfinite(T) and T > 0.0):
        raise ValueError(f'T must be finite and > 0, got {T!r}')
    if (F is None) != (gamma is None):
        raise ValueError('F and gamma must be given together (the game) or not at all (LQR)')
    f: np.ndarray | None = None
    s = b @ np.linalg.solve(r, b.T)
    if F is not None and gamma is not None:
        f = np.array(F, dtype=float, ndmin=2)
        f = _as_matrix('F', f, (n, f.shape[1] if f.ndim == 2 else -1))
        if not (math.isfinite(gamma) and gamma > 0.0):
            raise ValueError(f'gamma must be finite and > 0, got {gamma!r}')
        # The game term enters with the opposite sign of the control term, so both
        # fold into one quadratic coefficient.
        s = s - (f @ f.T) / gamma**2
    s = 0.5 * (s + s.T)

    def rhs(_tau: float, y: np.ndarray) -> np.ndarray:
        p = y.reshape(n, n)
        dp = a.T @ p + p @ a + mm - p @ s @ p
        # Symmetrising the derivative keeps round-off from growing an antisymmetric part.
        return (0.5 * (dp + dp.T)).reshape(-1)

    scale = max(1.0, float(np.abs(p_t).max()), float(np.abs(mm).max()) * T)
    limit = escape_norm * scale

    def blow_up(_tau: float, y: np.ndarray) -> float:
        return limit - float(np.abs(y).max())

    blow_up.terminal = True  # type: ignore[attr-defined]
    blow_up.direction = -1  # type: ignore[attr-defined]

    res = solve_ivp(
        rhs,
        (0.0, T),
        (0.5 * (p_t + p_t.T)).reshape(-1),
        method='DOP853',
        rtol=rtol,
        atol=atol * scale,
        dense_output=True,
        events=blow_up,
    )
    if res.status == 1:
        assert res.t_events is not None
        tau_e = float(res.t_events[0][0])
        raise RiccatiEscape(
            f'Riccati solution escapes at time-to-go {tau_e:.6g} s < T = {T:.6g} s', tau_e
        )
    if res.status != 0:
        # Near an escape the step size collapses before the norm test fires.
        tau_e = float(res.t[-1])
        raise RiccatiEscape(
            f'Riccati integration failed at time-to-go {tau_e:.6g} s '
            f'(likely a finite escape): {res.message}',
            tau_e,
        )
    return RiccatiSolution(res.sol, n, float(T), b, r, f, gamma)


def _game_bounded(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    m: npt.ArrayLike,
    r: npt.ArrayLike,
    p_t: npt.ArrayLike,
    T: float,
    f: npt.ArrayLike,
    gamma: float,
) -> bool:
    try:
        # Looser tolerances and escape threshold: only boundedness matters here, and
        # a solution that reaches 1e6 times its scale is within ~1e-6 of gamma*, far
        # finer than the bisection tolerance.
        solve_riccati(a, b, m, r, p_t, T, f, gamma, escape_norm=1e6, rtol=1e-7, atol=1e-9)
    except RiccatiEscape:
        return False
    return True


def game_gamma_bound(
    A: npt.ArrayLike,
    B: npt.ArrayLike,
    M: npt.ArrayLike,
    R: npt.ArrayLike,
    P_T: npt.ArrayLike,
    T: float,
    F: npt.ArrayLike,
    tol: float = 1e-4,
) -> float:
    """Smallest ``gamma`` for which the game Riccati equation stays bounded on ``[0, T]``.

    This is the finite-horizon H-infinity bound gamma*: any attenuation level above
    it has a saddle point (robust paper, Theorem 1).  ``P`` decreases monotonically as
    ``gamma`` grows, so bisection on boundedness is valid.

    Parameters
    ----------
    A, B, M, R, P_T, T, F
        As in :func:`solve_riccati`.
    tol : float
        Absolute tolerance on gamma; the result is an upper bracket (bounded).

    Returns
    -------
    float
        gamma* within ``tol`` from above; 0.0 when the game is bounded for every
        gamma down to ``tol`` (e.g. ``F = 0``).
    """
    if not tol > 0.0:
        raise ValueError(f'tol must be > 0, got {tol!r}')
    cache: dict[float, bool] = {}

    def bounded(gamma: float) -> bool:
        if gamma not in cache:
            cache[gamma] = _game_bounded(A, B, M, R, P_T, T, F, gamma)
        return cache[gamma]

    hi = 1.0
    while not bounded(hi):
        hi *= 2.0
        if hi > 1e12:
            raise RiccatiEscape(
                'no gamma up to 1e12 keeps the game bounded (the LQR itself escapes?)', 0.0
            )
    lo = hi / 2.0
    while bounded(lo):
        hi = lo
        lo /= 2.0
        if lo < tol:
            return 0.0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if bounded(mid):
            hi = mid
        else:
            lo = mid
    return hi
