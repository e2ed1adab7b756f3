"""Receding-horizon actor-critic on the compensated model (VF-LPC §IV-D, eqs. 25-39).

Within each prediction horizon of N steps, LPC learns the value function by dual
heuristic programming: the critic approximates the costate ``lambda_k = dV_k/dx_k``
(eqs. 31, 36), the actor the input minimising ``l_k + V_{k+1}`` (eqs. 32, 34), and
gradient steps on their errors (37)-(38) (eq. 39) iterate to the horizon's optimum.
On the linearised compensated model (eq. 22), ``x_{k+1} = A_k x_k + B_k u_k + c_k``, with
the step cost (24) expanded to second order (Gauss-Newton for the barrier), the exact
critic of every stage is affine in x and the exact actor's inputs solve one quadratic
programme in the whole input sequence ``U = (u_0, ..., u_{N-1})``. We solve that
programme directly instead of by gradient steps (the gradient steps converge to its
solution; here each iteration lands on it), in condensed form:
``X = Phi x_0 + Gamma U + s``, ``min ½ Uᵀ H U + gᵀ U`` on the actuator box
``|u| <= u_max`` by a projected Newton method (Bertsekas 1982). The costates of the
critic are ``lambda = Gammaᵀ``-weighted gradients of that programme and need not be
formed. A backtracking step on the true barrier cost accepts the new inputs.

Why condensed rather than the stage-by-stage sweep (iLQR, the same optimum): a
20-stage sweep is ~40 small numpy calls per stage, which on this machine costs several
milliseconds; the condensed form is a dozen array operations on a 40 x 40 system.
Warm start: the last control step's inputs shifted by one stage, so learning carries over
from one horizon to the next as in LPC (Xu et al. 2018). The terminal weight P_T is the
discrete-time Riccati solution of the nominal model (as in [11]).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .barrier import EdgeSet, barrier_terms
from .config import LPCConfig

__all__ = ['Linearisation', 'HorizonSolution', 'RecedingHorizonActorCritic', 'box_qp']

# (xbar (N, n), ubar (N, m)) -> fbar (N, n), A (N, n, n), B (N, n, m)
Linearisation = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class HorizonSolution:
    """The predicted trajectory and inputs of one control step."""

    states: np.ndarray      # (N+1, n)
    inputs: np.ndarray      # (N, m), N
    cost: float
    iterations: int


def box_qp(H: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, x0: np.ndarray,
           max_iter: int = 20) -> np.ndarray:
    """Minimise ½ xᵀ H x + gᵀ x on lo <= x <= hi (H positive definite): projected Newton.

    Each iteration fixes the variables at a bound whose gradient pushes outward, takes the
    Newton step on the others and projects, with backtracking on the objective.
    """
    x = -np.linalg.solve(H, g)
    if np.all(x >= lo) and np.all(x <= hi):
        return x                       # the box is not active: the Newton point itself
    x = np.clip(x0, lo, hi)

    def f(v: np.ndarray) -> float:
        return float(0.5 * v @ H @ v + g @ v)

    fx = f(x)
    for _ in range(max_iter):
        grad = H @ x + g
        fixed = ((x <= lo) & (grad > 0.0)) | ((x >= hi) & (grad < 0.0))
        free = ~fixed
        if not free.any():
            break
        step = np.zeros_like(x)
        step[free] = -np.linalg.solve(H[np.ix_(free, free)], grad[free])
        alpha, improved = 1.0, False
        for _ in range(8):
            cand = np.clip(x + alpha * step, lo, hi)
            fc = f(cand)
            if fc <= fx - 1e-12 * abs(fx) - 1e-15:
                improved = True
                break
            alpha *= 0.5
        if not improved:
            break
        converged = np.max(np.abs(cand - x)) <= 1e-9 * (1.0 + np.max(np.abs(x)))
        x, fx = cand, fc
        if converged:
            break
    return x


class RecedingHorizonActorCritic:
    """Solve the N-step tracking problem with barrier and input box, warm-started.

    Parameters
    ----------
    config : LPCConfig
    terminal : numpy.ndarray, shape (n, n)
        P_T of the terminal cost ``(x_N - r_N)ᵀ P_T (x_N - r_N)``.
    n, m : int
        State and input dimensions (positions are the first two states).
    """

    def __init__(self, config: LPCConfig, terminal: np.ndarray, n: int, m: int) -> None:
        self.config = config
        self.n, self.m = n, m
        q = np.zeros(n)
        q[:2] = config.q_position
        q[2:4] = config.q_velocity
        self.Q = np.diag(q)
        self.R = config.r_force * np.eye(m)
        self.P = np.asarray(terminal, dtype=float)
        N = config.horizon_steps
        self._lo = -config.force_limit * np.ones(N * m)
        self._hi = config.force_limit * np.ones(N * m)
        self._weights = np.concatenate((np.broadcast_to(self.Q, (N - 1, n, n)),
                                        self.P[None]))          # stages 1..N
        self._R2 = np.kron(np.eye(N), 2.0 * self.R)
        self._us: np.ndarray | None = None
        self._xs: np.ndarray | None = None
        self._edges: EdgeSet | None = None
        self._edge_polys: list[np.ndarray] = []

    def reset(self) -> None:
        """Forget the warm start."""
        self._us = self._xs = None

    def _condense(self, x0: np.ndarray, fbar: np.ndarray, A: np.ndarray, B: np.ndarray,
                  xbar: np.ndarray, ubar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Phi x0 + s and Gamma of X = (x_1..x_N) for the model linearised at (xbar, ubar)."""
        N, n, m = len(A), self.n, self.m
        c = fbar - np.einsum('kij,kj->ki', A, xbar) - np.einsum('kij,kj->ki', B, ubar)
        free = np.empty((N, n))
        gam = np.zeros((N, n, N * m))
        x, g = x0, np.zeros((n, N * m))
        for k in range(N):
            x = A[k] @ x + c[k]
            g = A[k] @ g
            g[:, k * m:(k + 1) * m] += B[k]
            free[k], gam[k] = x, g
        return free, gam

    def _stage_cost(self, xs: np.ndarray, us: np.ndarray, ref: np.ndarray,
                    edges: EdgeSet) -> tuple[float, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Cost of a trajectory and its barrier terms (value, gradient, Hessian)."""
        cfg = self.config
        e = xs - ref[1:]
        bar = barrier_terms(xs[:, :2], edges, cfg.barrier_weight, cfg.barrier_rate,
                            cfg.barrier_offset)
        run = float(np.einsum('ki,kij,kj->', e, self._weights, e)
                    + np.einsum('ki,ij,kj->', us, self.R, us) + bar[0].sum())
        return run, bar

    def solve(self, x0: np.ndarray, ref: np.ndarray, linearise: Linearisation,
              obstacles: Sequence[np.ndarray]) -> HorizonSolution:
        """One control step: the horizon's trajectory and inputs; apply ``inputs[0]``.

        Parameters
        ----------
        x0 : (n,) current state.
        ref : (N+1, n) reference states at t, t + dt, ..., t + N dt.
        linearise : the compensated model's values and Jacobians along a trajectory.
        obstacles : polygons carrying the barrier.
        """
        cfg = self.config
        if self._edges is None or len(obstacles) != len(self._edge_polys) or any(
                a is not b for a, b in zip(obstacles, self._edge_polys)):
            self._edges, self._edge_polys = EdgeSet(obstacles), list(obstacles)
        edges = self._edges
        N, m = cfg.horizon_steps, self.m
        if self._us is None or self._xs is None:
            us, xbar = np.zeros((N, m)), np.repeat(x0[None], N, axis=0)
        else:                            # the last solution, one stage on
            us = np.vstack((self._us[1:], self._us[-1:]))
            xbar = np.vstack((x0[None], self._xs[1:], self._xs[-1:]))[:N]
        fbar, A, B = linearise(xbar, us)
        free, gam = self._condense(x0, fbar, A, B, xbar, us)
        U = us.reshape(-1)
        xs = free + gam @ U
        cost, bar = self._stage_cost(xs, us, ref, edges)
        R2 = self._R2
        done = 0
        for it in range(cfg.iterations):
            if it:
                xbar = np.vstack((x0[None], xs[:-1]))
                fbar, A, B = linearise(xbar, us)
                free, gam = self._condense(x0, fbar, A, B, xbar, us)
                xs = free + gam @ U
                cost, bar = self._stage_cost(xs, us, ref, edges)
            # Critic: second-order expansion of the stage costs at the current trajectory.
            W = 2.0 * self._weights.copy()
            w = 2.0 * np.einsum('kij,kj->ki', self._weights, xs - ref[1:])
            W[:, :2, :2] += bar[2]
            w[:, :2] += bar[1]
            # Gammaᵀ W Gamma as one (N n) x (N m) product (BLAS; einsum was 5x slower).
            G2 = gam.reshape(N * self.n, N * m)
            H = G2.T @ np.matmul(W, gam).reshape(N * self.n, N * m) + R2
            # gradient of the model at U: Gammaᵀ w + 2 R U; Newton about U.
            grad = G2.T @ w.reshape(-1) + R2 @ U
            g = grad - H @ U
            target = box_qp(H, g, self._lo, self._hi, U)
            done += 1
            # Actor: accept the new inputs by backtracking on the barrier's true cost.
            for alpha in (1.0, 0.5, 0.25):
                cand = U + alpha * (target - U)
                cand_u = cand.reshape(N, m)
                cand_x = free + gam @ cand
                c_cost, c_bar = self._stage_cost(cand_x, cand_u, ref, edges)
                if c_cost < cost:
                    U, us, xs, cost, bar = cand, cand_u, cand_x, c_cost, c_bar
                    break
        self._us, self._xs = us, xs
        return HorizonSolution(np.vstack((x0[None], xs)), us.copy(), cost, done)
