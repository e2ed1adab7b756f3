"""How far a bounded residual can push the closed loop off a straight leg (``docs/margins.md`` §4).

On a leg, in its coordinates, the observer's model (:mod:`.observer`) and the controller's
policy u_k = −K̂(τ_k) x̄_k + p_k (p_k the probing noise) give

    x̄_{k+1} = A_k x̄_k + h + Γ̂ p_k + w_k,      A_k = Φ̂ − Γ̂ K̂(τ_k),  τ_k = T − kΔt,

with h a constant drive (zero when the model's frame is the leg's) and w_k the residual,
split into its field d(p_k), bounded per component by |d_i| <= r s_i (a level r of the bank
times a shape s), and a zero-mean noise ε_k. By superposition
x̄_k = x̄_k^nom + Σ_{j<k} Ψ(k, j+1)(w_j + Γ̂ p_j), where x̄^nom is the undisturbed response
from the leg's start and Ψ(k, i) = A_{k−1}⋯A_i (Ψ(k, k) = I). The leg's deviation is the
component of the position Px̄ along the leg's unit normal c, so

    |cᵀPx̄_k| ≤ |cᵀPx̄_k^nom| + r Σ_{j<k} Σ_i s_i |cᵀPΨ(k, j+1)e_i| + |cᵀP x̄_k^rand|,

where the middle term is attained by d_j = r s ∘ sign(cᵀPΨ(k, j+1)) (:func:`tube_gains`) and
x̄^rand, driven by the noise and the probing, is Gaussian with a covariance propagated
exactly (:func:`random_deviation`). A future leg's direction is not known, so the worst-case
sum is maximised over c: it is a seminorm of c, and its maximum over the unit circle is at
most its maximum over D equally spaced directions of [0, π) divided by cos(π / 2D); the
random part takes the largest eigenvalue of the position covariance.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import numpy.typing as npt

__all__ = ['closed_loop', 'tube_gains', 'leg_tube', 'leg_tube_terms', 'position_covariance',
           'random_deviation', 'leg_spread',
           'nominal_deviation', 'nominal_path', 'tube_margin']


def closed_loop(phi: np.ndarray, gamma: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """A_k = Φ̂ − Γ̂ K̂_k for gains (N, m, n): shape (N, n, n)."""
    return phi[None] - np.einsum('im,kmj->kij', gamma, gains)


EXPANSION_LIMIT = 0.005
"""Largest spectral radius − 1 of a step of the learned closed loop for which its tube is
believed: the true rover's closed loop at the zero gain has an eigenvalue of exactly 1 (the
position of a robot without a spring), which an estimate puts a little either side; an early
model with a clearly expanding mode (radius 1.05: ×1.7e4 over a 10 s leg at Δt = 0.05 s)
gave margins of up to 1e9 m."""


def expanding(phi: np.ndarray, gamma: np.ndarray, gains: np.ndarray,
              limit: float = EXPANSION_LIMIT) -> bool:
    """Whether some step of the closed loop Φ̂ − Γ̂K̂_k has a spectral radius above 1 + limit."""
    radius = np.abs(np.linalg.eigvals(closed_loop(phi, gamma, gains))).max()
    return bool(radius > 1.0 + limit)


def _directions(count: int) -> np.ndarray:
    ang = math.pi * np.arange(count) / count
    return np.column_stack([np.cos(ang), np.sin(ang)])


def _projected_sums(a: np.ndarray, s: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Σ_{j<k} Σ_i s_i |cᵀPΨ(k, j+1)e_i| for k = 1..N and each row c of ``c``: (N, D)."""
    out = np.zeros((a.shape[0], len(c)))
    for k, proj in enumerate(_projections(a, c)):
        out[k] = (np.abs(proj) @ s).sum(axis=0)
    return out


def _projections(a: np.ndarray, c: np.ndarray) -> Iterator[np.ndarray]:
    """cᵀPΨ(k+1, j+1) for j = 0..k, as a (k+1, D, n) array, for k = 0..N-1 in turn."""
    N, n = a.shape[0], a.shape[1]
    # At iteration k, blocks = [Ψ(k+1, 1), ..., Ψ(k+1, k+1) = I]; Ψ(k+1, j+1) = A_k Ψ(k, j+1)
    # multiplies on the left, so whole blocks are kept, not just their position rows.
    # Kept right-aligned in one array: at iteration k, blocks[N-1-k:] (oldest first).
    blocks = np.empty((N, n, n))
    blocks[N - 1] = np.eye(n)
    for k in range(N):
        if k:
            blocks[N - 1 - k:N - 1] = a[k] @ blocks[N - k:]
            blocks[N - 1] = np.eye(n)
        yield c @ blocks[N - 1 - k:, :2, :]


def leg_tube_terms(phi: np.ndarray, gamma: np.ndarray, gains: np.ndarray,
                   shape: npt.ArrayLike, normal: npt.ArrayLike | None,
                   directions: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """The tube's terms step by step, for a level that changes along the leg.

    Returns (worst (N, N, D), along (N, N)): entry [k, j] is Σ_i s_i |cᵀPΨ(k+1, j+1)e_i|,
    the deviation at step k + 1 per unit level of the residual at step j (zero for j > k),
    for each of the D directions of :func:`tube_gains` and for the unit vector ``normal``
    (zeros when None). With a level ℓ_j per step, the deviation at step k + 1 is at most
    max_c Σ_j ℓ_j worst[k, j, c] / cos(π/2D) in any direction, Σ_j ℓ_j along[k, j] across
    the leg's line.
    """
    s = np.asarray(shape, dtype=float)
    a = closed_loop(phi, gamma, gains)
    N = a.shape[0]
    c = _directions(directions)
    if normal is not None:
        c = np.vstack([c, np.asarray(normal, dtype=float).reshape(1, 2)])
    terms = np.zeros((N, N, len(c)))
    for k, proj in enumerate(_projections(a, c)):
        terms[k, :k + 1] = np.abs(proj) @ s
    along = terms[:, :, directions] if normal is not None else np.zeros((N, N))
    return terms[:, :, :directions], along


def tube_gains(phi: np.ndarray, gamma: np.ndarray, gains: np.ndarray, shape: npt.ArrayLike,
               directions: int = 16) -> np.ndarray:
    """max_c Σ_{j<k} Σ_i s_i |cᵀPΨ(k, j+1)e_i| for k = 1..N: deviation (m) per unit level.

    Parameters
    ----------
    phi, gamma
        Φ̂ (n, n) and Γ̂ (n, m) of the one-step model.
    gains
        K̂(τ_k) (N, m, n) at τ_k = T − kΔt: the controller's schedule over a whole leg.
    shape
        s (n,): the residual's bound per component per unit level, state units per step.
    directions
        D, directions of the leg's normal the sums are maximised over.

    Returns
    -------
    numpy.ndarray, shape (N,)
        Entry k − 1 is the gain at step k; multiply by the level r.
    """
    return leg_tube(phi, gamma, gains, shape, None, directions)[0]


def leg_tube(phi: np.ndarray, gamma: np.ndarray, gains: np.ndarray, shape: npt.ArrayLike,
             normal: npt.ArrayLike | None, directions: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Per unit level: the tube in the worst direction, and along one leg's ``normal``.

    Returns (worst, along), each (N,): ``worst`` as :func:`tube_gains` (the radius of a disc
    about the undisturbed position that holds the disturbed one), ``along`` the exact sum for
    the unit vector ``normal`` (zeros when it is None): the bound on the deviation across
    that leg's line.
    """
    s = np.asarray(shape, dtype=float)
    a = closed_loop(phi, gamma, gains)
    c = _directions(directions)
    if normal is not None:
        c = np.vstack([c, np.asarray(normal, dtype=float).reshape(1, 2)])
    sums = _projected_sums(a, s, c)
    worst = sums[:, :directions].max(axis=1) / math.cos(math.pi / (2 * directions))
    along = sums[:, directions] if normal is not None else np.zeros(len(sums))
    return worst, along


def position_covariance(phi: np.ndarray, gamma: np.ndarray, gains: np.ndarray,
                        noise: npt.ArrayLike, probing: npt.ArrayLike,
                        correlation: float) -> np.ndarray:
    """(Σ_xx, Σ_yy, Σ_xy) (N, 3) of the position's random part, k = 1..N.

    The residual noise is white with standard deviations ``noise`` (n,); the probing is an
    AR(1) (the controller's Ornstein-Uhlenbeck noise sampled every Δt) with stationary
    standard deviations ``probing`` (m,) and lag-one ``correlation``; both start the leg
    stationary and the deviation starts at zero. The covariance of (x̄^rand, p) is propagated
    exactly: Σ_{k+1} = Ā_k Σ_k Ā_kᵀ + Q with Ā_k = [[A_k, Γ̂], [0, a I]].
    """
    a = closed_loop(phi, gamma, gains)
    N, n = a.shape[0], a.shape[1]
    m = gamma.shape[1]
    rho = float(correlation)
    sp2 = np.asarray(probing, dtype=float) ** 2 * np.ones(m)
    q = np.diag(np.concatenate([np.asarray(noise, dtype=float) ** 2 * np.ones(n),
                                (1.0 - rho * rho) * sp2]))
    cov = np.diag(np.concatenate([np.zeros(n), sp2]))
    big = np.zeros((n + m, n + m))
    big[:n, n:] = gamma
    big[n:, n:] = rho * np.eye(m)
    pos = np.zeros((N, 3))
    for k in range(N):
        big[:n, :n] = a[k]
        cov = big @ cov @ big.T + q
        pos[k] = cov[0, 0], cov[1, 1], cov[0, 1]
    return pos


def random_deviation(phi: np.ndarray, gamma: np.ndarray, gains: np.ndarray,
                     noise: npt.ArrayLike, probing: npt.ArrayLike,
                     correlation: float) -> np.ndarray:
    """Standard deviation (m) of the position along the worst normal, k = 1..N.

    See :func:`position_covariance` for the model of the noise and the probing.
    """
    return leg_spread(position_covariance(phi, gamma, gains, noise, probing, correlation),
                      None)[0]


def leg_spread(pos: np.ndarray, normal: npt.ArrayLike | None) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviations (worst direction, along ``normal``) from :func:`position_covariance`.

    The worst direction's is √λ_max of the 2 × 2 covariance; ``normal`` None gives zeros for
    the second.
    """
    half = 0.5 * (pos[:, 0] + pos[:, 1])
    top = half + np.sqrt((0.5 * (pos[:, 0] - pos[:, 1])) ** 2 + pos[:, 2] ** 2)
    worst = np.sqrt(np.maximum(top, 0.0))
    if normal is None:
        return worst, np.zeros(len(pos))
    c = np.asarray(normal, dtype=float)
    var = c[0] ** 2 * pos[:, 0] + c[1] ** 2 * pos[:, 1] + 2.0 * c[0] * c[1] * pos[:, 2]
    return worst, np.sqrt(np.maximum(var, 0.0))


def nominal_deviation(phi: np.ndarray, gamma: np.ndarray, offset: np.ndarray,
                      gains: np.ndarray, starts: npt.ArrayLike,
                      targets: npt.ArrayLike) -> np.ndarray:
    """max_k |cᵀPx̄_k^nom| of legs started at ``starts`` toward ``targets`` under the model.

    Parameters
    ----------
    phi, gamma
        Φ̂, Γ̂ of the one-step model.
    offset
        H (n, 2): the constant drive h = H p_r of a leg toward p_r in its coordinates; zero
        when the model's frame is the leg's, (Φ̂ − I)[:, :2] when it is the world's.
    gains
        K̂(τ_k) (N, m, n).
    starts
        Full states at the legs' starts (L, n), world frame.
    targets
        The legs' target positions (L, 2); the normal c is that of start → target.
    """
    x = np.array(starts, dtype=float, ndmin=2)
    tgt = np.array(targets, dtype=float, ndmin=2)
    xbar = x.copy()
    xbar[:, :2] -= tgt
    along = -xbar[:, :2]
    length = np.linalg.norm(along, axis=1, keepdims=True)
    normal = np.column_stack([-along[:, 1], along[:, 0]]) / np.where(length > 0, length, 1.0)
    # A zero-length leg has no line: its deviation is the distance from the target, as
    # :func:`rrtq_planner.safety.kinodynamic_distance` takes RRT-QX eq. 6 there.
    point = length[:, 0] < 1e-12
    drive = tgt @ offset.T                                         # Ĥ p_r, (L, n)
    worst = np.zeros(len(x))
    for a_k in closed_loop(phi, gamma, gains):
        xbar = xbar @ a_k.T + drive
        dev = np.where(point, np.linalg.norm(xbar[:, :2], axis=1),
                       np.abs((normal * xbar[:, :2]).sum(axis=1)))
        worst = np.maximum(worst, dev)
    return worst


def nominal_path(phi: np.ndarray, gamma: np.ndarray, offset: np.ndarray, gains: np.ndarray,
                 start: npt.ArrayLike, target: npt.ArrayLike,
                 origin: npt.ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The undisturbed response of one leg under the model: positions and deviations.

    Returns (positions (N, 2), world frame, at k = 1..N; |cᵀPx̄_k^nom| (N,), the distance from
    the leg's line through ``origin`` (default the start's position) and the target, or from
    the target for a zero-length leg) for the leg from the full state ``start`` toward the
    position ``target``; see :func:`nominal_deviation` for ``offset``.
    """
    x = np.array(start, dtype=float)
    tgt = np.array(target, dtype=float)[:2]
    xbar = x.copy()
    xbar[:2] -= tgt
    along = (x[:2] if origin is None else np.asarray(origin, dtype=float)[:2]) - tgt
    along = -along
    length = float(np.linalg.norm(along))
    drive = offset @ tgt
    pos = np.zeros((len(gains), 2))
    for k, a_k in enumerate(closed_loop(phi, gamma, gains)):
        xbar = a_k @ xbar + drive
        pos[k] = xbar[:2]
    if length < 1e-12:
        dev = np.linalg.norm(pos, axis=1)
    else:
        normal = np.array([-along[1], along[0]]) / length
        dev = np.abs(pos @ normal)
    return pos + tgt, dev


def tube_margin(residual_gains: np.ndarray, bound: float, spread: np.ndarray,
                z: float) -> float:
    """The margin max_k of r·gain_k + z·std_k, m.

    The worst-case part for the level r plus z standard deviations of the random part (z of
    the probability the margin is to hold with).
    """
    return float((bound * residual_gains + z * spread).max())
