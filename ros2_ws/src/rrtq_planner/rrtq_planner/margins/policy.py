"""The margin policy: what the safety side feeds per step, and the margin it gets back.

Three modes (``docs/margins.md``):

* ``running_max`` — the running maximum of D_rob since the start (RRT-QX eqs. 6-7), exactly
  what :class:`rrtq_planner.safety.SafetyMonitor` does;
* ``conformal`` — a conformal quantile of the last legs' scores (:mod:`.conformal`);
* ``learned_bound`` — the deviation a learned, confidence-bounded residual can cause in the
  current closed loop (:mod:`.learned`).

Every mode answers the margin (m, without the robot radius, which the caller adds) with the
same diagnostics. In ``conformal`` and ``learned_bound`` a deviation above the current margin
raises it at once for the rest of the leg, is counted, and is flagged for the log; the
margin for the next legs then comes from the evidence again.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np
import numpy.typing as npt

from rrtq_common.geometry import kinodynamic_distance

from .conformal import ConformalConfig, ConformalQuantile

__all__ = ['MarginMode', 'LegInfo', 'MarginSample', 'MarginStatus', 'MarginPolicy',
           'LegTracker', 'RunningMaxPolicy', 'ConformalPolicy']

Array = npt.NDArray[np.float64]


class MarginMode(enum.StrEnum):
    """How the obstacles' growth is chosen (``safety.margin``)."""

    RUNNING_MAX = 'running_max'
    CONFORMAL = 'conformal'
    LEARNED_BOUND = 'learned_bound'


@dataclasses.dataclass(frozen=True)
class LegInfo:
    """The controller's current leg (``/controller/state``)."""

    index: int
    start: Array
    """(2,), m: where the leg started."""
    target: Array
    """(2,), m: the leg's target waypoint."""
    d0: float
    """D0, m (RRT-QX eq. 4); a leg with D0 <= 0 is not measured (as the safety node does)."""


@dataclasses.dataclass(frozen=True)
class MarginSample:
    """What the safety side knows at one step t.

    ``leg``, ``applied``, ``probing`` and ``gain`` are those of the controller's state of the
    step before (the command that acted over [t − Δt, t)), as the safety node receives them.
    """

    t: float
    """s."""
    state: Array
    """(n,), the measured state at t, world frame (position first, m; velocity, m/s)."""
    leg: LegInfo | None = None
    applied: Array | None = None
    """(m,), N: the force commanded over [t − Δt, t)."""
    probing: Array | None = None
    """(m,), N: the probing-noise part of ``applied``."""
    gain: Callable[[float], Array] | None = None
    """K̂(τ) (m x n) of the controller's actor, u = −K̂(τ)x̄ + probing."""
    horizon: float = 0.0
    """T, s: the controller's leg horizon (τ runs from T to 0 on a leg)."""


@dataclasses.dataclass(frozen=True)
class MarginStatus:
    """The answer of one step."""

    mode: MarginMode
    margin: float
    """m: what obstacles are grown by now (the robot radius is the caller's to add)."""
    leg_margin: float
    """m: the margin in force when the current leg started; a leg whose largest deviation
    exceeds it is a violation (this is what coverage is checked against)."""
    bound: float
    """running_max: max D_rob (m); conformal: the quantile of the window (m, inf when too few
    scores); learned_bound: the bank's bound r_k on the residual field, as an acceleration
    (m/s², inf before the first)."""
    confidence: float
    """1 − δ (conformal adaptive: 1 − δ_t)."""
    samples: int
    """running_max: legs; conformal: scores in the window; learned_bound: residuals in the window."""
    violations: int
    """Legs whose largest deviation exceeded their ``leg_margin``."""
    d_rob: float
    """m, D_rob at this step (RRT-QX eq. 6)."""
    d_rob_max: float
    """m, its running maximum since the start."""
    violation: bool = False
    """True at the step a deviation first exceeds the current leg's margin (log it)."""
    bound_violations: int = 0
    """learned_bound: residuals that exceeded the bound and raised it (Alg. 1, up at once)."""
    leg_deviation: float = 0.0
    """m, the current leg's largest D_rob so far: its score when it ends."""
    legs: int = 0
    """Legs measured so far, the current one included (a calibration file is read off
    ``leg_deviation`` at the last step of each)."""
    local: Callable[[str, np.ndarray], float] | None = None
    """learned_bound, once it has a bound: the margin (m) of one obstacle (id, polygon (k, 2))
    by where it is (docs/margins.md §5.1); None: every obstacle is grown by ``margin``."""
    leg_tube: float = 0.0
    """learned_bound: m, the tube predicted for the current leg at its start before any
    calibration (a leg's normalized score is its deviation over this); 0 when the leg
    started without a contracting model, or in the other modes."""
    scale: float = 1.0
    """learned_bound, conformal: the calibrated factor on the tube (1: uncalibrated)."""
    leg_refuted: bool = False
    """learned_bound: the current leg's tube rests on a level residuals raised above the prior
    bound (its normalized score belongs to the refuted category, docs/margins.md §10)."""


class MarginPolicy(Protocol):
    """One step in, the margin out."""

    mode: MarginMode

    def step(self, sample: MarginSample) -> MarginStatus: ...

    @property
    def scores(self) -> list[float]:
        """Largest deviation of each finished leg, oldest first (for a calibration file)."""
        ...


class LegTracker:
    """D_rob per step, its running maximum, and each leg's score when the leg ends."""

    def __init__(self) -> None:
        self.d_rob = 0.0
        self.d_rob_max = 0.0
        self.leg: LegInfo | None = None
        self.leg_max = 0.0
        self.scores: list[float] = []
        self.started: list[tuple[int, Array, Array]] = []
        """(index, full state at the leg's start, target) of every leg seen."""
        self.durations: list[int] = []
        """Steps measured on each finished leg."""
        self.leg_steps = 0
        self.previous_state: Array | None = None
        self.new_leg = False
        """Whether a leg started at the last update."""

    def update(self, sample: MarginSample) -> float | None:
        """Account a step; returns the score of the leg that ended at it, if any."""
        ended = None
        self.new_leg = False
        leg = sample.leg
        state = np.asarray(sample.state, dtype=float)
        if leg is not None and leg.d0 > 0.0:
            if self.leg is None or leg.index != self.leg.index:
                if self.leg is not None:
                    ended = self.leg_max
                    self.scores.append(ended)
                    self.durations.append(self.leg_steps)
                self.leg_steps = 0
                start = self.previous_state if self.previous_state is not None else state
                self.started.append((leg.index, start.copy(), np.asarray(leg.target, float)[:2]))
                self.new_leg = True
            self.leg, self.leg_max = leg, (0.0 if self.new_leg else self.leg_max)
            self.d_rob = kinodynamic_distance(leg.start, leg.target, state[:2])
            self.d_rob_max = max(self.d_rob_max, self.d_rob)
            self.leg_max = max(self.leg_max, self.d_rob)
            self.leg_steps += 1
        self.previous_state = state.copy()
        return ended

    @property
    def count(self) -> int:
        """Legs measured so far, the current one included."""
        return len(self.scores) + (self.leg is not None)

    def finish(self) -> None:
        """Close the current leg (end of the run): its score joins :attr:`scores`."""
        if self.leg is not None:
            self.scores.append(self.leg_max)
            self.durations.append(self.leg_steps)
            self.leg = None


class RunningMaxPolicy:
    """The paper's margin: max D_rob since the start (RRT-QX eqs. 6-7)."""

    mode = MarginMode.RUNNING_MAX

    def __init__(self) -> None:
        self.legs = LegTracker()

    @property
    def scores(self) -> list[float]:
        return self.legs.scores

    def step(self, sample: MarginSample) -> MarginStatus:
        self.legs.update(sample)
        t = self.legs
        return MarginStatus(self.mode, t.d_rob_max, t.d_rob_max, t.d_rob_max, 1.0, t.count, 0,
                            t.d_rob, t.d_rob_max, leg_deviation=t.leg_max, legs=t.count)


class ConformalPolicy:
    """The conformal quantile of the last legs' scores; the conservative start until enough.

    Parameters
    ----------
    config
        Confidence, window, adaptation.
    initial_margin
        m: the margin while the window cannot certify the level (too few scores, or δ_t
        pushed to 0 by misses); None: the running maximum of D_rob (the paper's margin).
    calibration
        Scores of earlier runs, oldest first (:mod:`.calibration`).
    """

    mode = MarginMode.CONFORMAL

    def __init__(self, config: ConformalConfig, initial_margin: float | None = None,
                 calibration: Sequence[float] = ()) -> None:
        self.config = config
        self.initial_margin = initial_margin
        self.quantile = ConformalQuantile(config, calibration)
        self.legs = LegTracker()
        self.leg_quantile = self.quantile.margin
        self.leg_warmup = self.quantile.warming_up
        self.leg_margin = self._prediction()
        self.flagged = False
        self.misses = 0

    @property
    def scores(self) -> list[float]:
        return self.legs.scores

    def _prediction(self) -> float:
        q = self.leg_quantile
        if math.isinf(q):
            return self.legs.d_rob_max if self.initial_margin is None else self.initial_margin
        return q

    def step(self, sample: MarginSample) -> MarginStatus:
        ended = self.legs.update(sample)
        if ended is not None:
            # The adaptive level learns from the misses of the margin in force (published),
            # also when δ_t has made the quantile infinite and the conservative start stood
            # in for it: then Gibbs & Candès' identity, miss rate = δ − (δ_T − δ_0)/(ηT),
            # is about what the planner was given, not about an infinite set nobody used.
            # Warm-up legs (too few scores for any level) do not move δ_t.
            self.quantile.observe(ended, self.leg_margin, adapt=not self.leg_warmup)
            self.misses += ended > self.leg_margin
        if self.legs.new_leg:                  # the prediction for the leg that starts
            self.leg_quantile = self.quantile.margin
            self.leg_warmup = self.quantile.warming_up
            self.leg_margin = self._prediction()
            self.flagged = False
        t = self.legs
        violation = t.leg is not None and t.leg_max > self.leg_margin and not self.flagged
        self.flagged |= violation
        return MarginStatus(
            self.mode, max(self.leg_margin, t.leg_max), self.leg_margin, self.quantile.margin,
            self.quantile.level, len(self.quantile.scores),
            self.misses + self.flagged, t.d_rob, t.d_rob_max, violation,
            leg_deviation=t.leg_max, legs=t.count)
