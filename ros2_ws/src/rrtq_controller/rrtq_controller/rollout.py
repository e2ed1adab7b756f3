"""Does a policy carry the robot away from its target? Its closed loop under the identified model.

The guard's other tests read a proposal through the critic that proposed it; where the
critic is biased they share its bias. Under odometry noise and a two-step actuation delay
the critic proposed gains whose position part changes sign at mid-horizon (K̂_yy(5 s) =
-14 N/m on the rover without a spring, where the optimum's is positive at every time to
go): the robot drove at its target for three seconds, turned, and left its leg at 1.5 m/s
until the divergence watch stopped it; twice in 20 missions it hit an obstacle or left the
world first. This test reads the proposal through the plant instead, as the observer has
identified it from odometry and commanded forces alone (:class:`observer.OneStepModel`:
Φ and the lagged Γ_j, so that the delay is in it).

A robot at rest at a unit offset from its target, starting at a time to go τ_s, is flown
by the proposal's gain K̂(τ) through the identified model to the end of the horizon,
every input lag at zero. Its offset at each later step is Ψ(τ_s → τ) e (Ψ the position
block of the closed loop's transition matrix), and the worst direction's growth is the
spectral norm ‖Ψ(τ_s → τ)‖. The proposal *carries the robot away* when, from some start,
that norm exceeds the one of the same model with no force at all (≥ 1: a robot that is
not pushed stays where it is, up to what the identified model's own drift makes of it) by a
factor beyond a tolerance. It is a comparison with doing nothing: a policy that makes a
robot at rest end up much farther from its target than standing still would is not a
controller for that target. The tolerance is the divergence watch's own (a leg diverges at
D > ``divergence_distance`` D0, twice the start by default: a relative excess of at most
``divergence_distance`` - 1 is a rollout the watch would let run), or what the policy in
use already does if that is more (the guard then stops an escalation, where it starts). The
finite-horizon LQ optimum passes: on this plant its position gain is positive at every time
to go and from rest it only ever closes the offset.

A policy can pass that test and still throw a moving robot: a velocity gain that feeds
speed back (anti-damping) beyond the plant's own damping does nothing to a robot at rest
whose position gain is near zero, and everything to one that moves. Against friction the
critic proposed such gains (+20 to +55 N s/m on both axes of a 45 kg/s base, position gain
near zero; before the observer modelled the friction, -371 N s/m on the diagonal of the
adopted K_v in another run took the robot to 6.5 m/s within a second, into an obstacle).
So the rollouts also start from a robot *moving* at unit speed at its target (every
state beyond the positions at unit size, the worst direction), and compare the growth of
those states, ‖Ψ_vv(τ_s → τ)‖, with coasting's (at least 1, as standing still's is): a
dissipative loop only slows the robot (its energy falls), and a speed that grows beyond
the same tolerance is a loop the plant's damping does not hold.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .observer import OneStepModel

Array = NDArray[np.float64]


@dataclass(frozen=True)
class AwayFrom:
    """Where a policy carries a robot at rest farther than standing still would."""

    start: float
    """τ_s (s): the time to go it started from."""
    tau: float
    """τ (s): where its offset was the largest against standing still."""
    growth: float
    """‖Ψ(τ_s → τ)‖ under the policy."""
    still: float
    """The same with no force (the identified model's own drift)."""
    moving: bool = False
    """From a robot moving at unit speed at its target (the growth of its speed), not at rest."""

    @property
    def excess(self) -> float:
        """``growth`` / ``still`` - 1: how much farther than standing still, relatively."""
        return self.growth / self.still - 1.0

    def __str__(self) -> str:
        if self.moving:
            return (f'speeds a moving robot up from time to go {self.start:.2f} s to '
                    f'{self.growth:.3g} x its speed at {self.tau:.2f} s (coasting: '
                    f'{self.still:.3g} x; excess {self.excess:.3g}) under the identified model')
        return (f'carries a robot at rest from time to go {self.start:.2f} s to '
                f'{self.growth:.3g} x its offset at {self.tau:.2f} s (standing still: '
                f'{self.still:.3g} x; excess {self.excess:.3g}) under the identified model')


def closed_loop(model: OneStepModel, gains: Array) -> Array:
    """The transition matrices of the delayed closed loop, one per step.

    ``gains`` (S, m, n): K̂ at each step, u_k = -K̂ x̄_k. State [x̄_k, u_{k-1}, ..., u_{k-J}],
    x̄_{k+1} = Φ x̄_k + Γ_0 u_k + Σ_{j>=1} Γ_j u_{k-j}. Returns (S, N, N), N = n + J m.
    """
    n, m = model.phi.shape[0], model.gammas.shape[2]
    lags = model.gammas.shape[0] - 1
    size = n + lags * m
    steps = len(gains)
    T = np.zeros((steps, size, size))
    T[:, :n, :n] = model.phi - np.einsum('im,smn->sin', model.gammas[0], gains)
    for j in range(1, lags + 1):
        T[:, :n, n + (j - 1) * m:n + j * m] = model.gammas[j]
    if lags:
        T[:, n:n + m, :n] = -gains
        for j in range(1, lags):
            T[:, n + j * m:n + (j + 1) * m, n + (j - 1) * m:n + j * m] = np.eye(m)
    return T


def fly(model: OneStepModel, gains: Array, x0: Array, inputs: Array | None = None,
        limit: float = np.inf) -> Array:
    """The states x̄_1 .. x̄_S of a robot flown from x̄0 through ``model``: (S, n).

    The force at step k is -K̂_k x̄_k (``gains`` (S, m, n)) plus ``inputs[k]`` (the open-loop
    part of what was applied: probing, a feed-forward; none by default), clipped at ±``limit``;
    nothing else acts (no push, no noise), and every input lag starts at zero.
    """
    n, lags = model.phi.shape[0], model.gammas.shape[0]
    x = np.asarray(x0, dtype=float).copy()
    past = np.zeros((lags, model.gammas.shape[2]))    # u_k, u_{k-1}, ..., u_{k-J}
    out = np.empty((len(gains), n))
    with np.errstate(over='ignore', invalid='ignore'):
        for k, K in enumerate(gains):
            u = -K @ x if inputs is None else inputs[k] - K @ x
            past = np.roll(past, 1, axis=0)
            past[0] = np.clip(u, -limit, limit)
            x = model.phi @ x + np.einsum('jnm,jm->n', model.gammas, past)
            out[k] = x
    return out


def spread(model: OneStepModel, gains: Array) -> Array:
    """The covariance of x̄_S built up by the model's unexplained part e over a closed loop.

    e white, ``residual_cov`` per step, through the closed loop of ``gains`` (S, m, n), from
    a known start: (n, n).
    """
    n = model.phi.shape[0]
    transitions = closed_loop(model, gains)
    P = np.zeros(transitions.shape[1:])
    with np.errstate(over='ignore', invalid='ignore'):
        for T in transitions:
            P = T @ P @ T.T
            P[:n, :n] += model.residual_cov
    return P[:n, :n]


def worst_growth(transitions: Array, positions: int, start: int,
                 states: slice | None = None) -> Array:
    """‖Ψ(start → k)‖ for k = start+1 .. S: the position block, from rest (S - start,).

    ``states``: another block of the state (its own start directions and growth), e.g.
    the velocities ``slice(m, n)``: from a robot moving at its target.
    """
    size = transitions.shape[1]
    block = slice(0, positions) if states is None else states
    width = len(range(size)[block])
    X = np.zeros((size, width))
    X[block, :] = np.eye(width)
    blocks = np.empty((len(transitions) - start, width, width))
    with np.errstate(over='ignore', invalid='ignore'):
        for i, T in enumerate(transitions[start:]):
            X = T @ X
            blocks[i] = X[block]
    # a loop (or an identified model) that grows without bound overflows: infinite growth
    out = np.full(len(blocks), np.inf)
    finite = np.isfinite(blocks).all(axis=(1, 2))
    out[finite] = np.linalg.norm(blocks[finite], 2, axis=(1, 2))
    return out


class Rollout:
    """The rollouts from rest of one identified model: standing still once, policies against it.

    From each time to go in ``starts`` to the end of the horizon, in steps of ``dt`` (see the
    module's docstring). Standing still depends on the model alone, so the guard builds this
    once per model and flies every proposal through it.
    """

    def __init__(self, model: OneStepModel, horizon: float, dt: float,
                 starts: Sequence[float] | Array) -> None:
        self.model, self.dt = model, dt
        self.m, n = model.gammas.shape[2], model.phi.shape[0]
        steps = max(int(round(horizon / dt)), 1)
        self.taus = horizon - dt * np.arange(steps)
        self.starts = [min(max(int(round((horizon - float(t)) / dt)), 0), steps - 1)
                       for t in starts]
        still = closed_loop(model, np.zeros((steps, self.m, n)))
        self._still = [np.maximum(worst_growth(still, self.m, k), 1.0) for k in self.starts]
        self._speeds = slice(self.m, n) if n > self.m else None
        """The states beyond the positions (the velocities), for the rollouts from motion."""
        self._coasting = ([np.maximum(worst_growth(still, self.m, k, self._speeds), 1.0)
                           for k in self.starts] if self._speeds is not None else [])

    def away(self, gain: Callable[[float], Array]) -> AwayFrom:
        """Where the policy ``gain`` (τ -> K̂(τ), m x n) carries a robot farthest away.

        The start and step of the largest excess over standing still (from rest at a unit
        offset) or over coasting (moving at unit speed at the target): negative where it
        closes the offset and slows the robot everywhere.
        """
        moved = closed_loop(self.model, np.array([gain(float(t)) for t in self.taus]))
        worst: AwayFrom | None = None
        families: list[tuple[list[Array], slice | None]] = [(self._still, None)]
        if self._speeds is not None:
            families.append((self._coasting, self._speeds))
        for bases, states in families:
            for start, base in zip(self.starts, bases, strict=True):
                ours = worst_growth(moved, self.m, start, states)
                with np.errstate(invalid='ignore'):
                    # where the model's own drift overflows too it tells nothing: no excess
                    ratio = np.where(np.isinf(base), 1.0, ours / base)
                k = int(np.argmax(ratio))
                if worst is None or ratio[k] - 1.0 > worst.excess:
                    tau = float(self.taus[start])
                    worst = AwayFrom(tau, tau - self.dt * (k + 1),
                                     float(ours[k]) if np.isfinite(base[k]) else 1.0,
                                     float(base[k]) if np.isfinite(base[k]) else 1.0,
                                     moving=states is not None)
        assert worst is not None, 'no start'
        return worst


def carries_away(model: OneStepModel, gain: Callable[[float], Array], horizon: float,
                 dt: float, starts: Sequence[float] | Array) -> AwayFrom:
    """:meth:`Rollout.away` of ``gain`` through ``model`` (one policy, one model)."""
    return Rollout(model, horizon, dt, starts).away(gain)
