"""``learned_bound``'s margin: the field's bound along the current leg, through the closed loop.

The half of :class:`.learned.LearnedBoundPolicy` that turns what it learned into margins (a
mixin; ``docs/margins.md`` §5-5.1): the current leg's undisturbed path and tube under the
controller's current gain (:meth:`LearnedMargin._new_tube`), the field's bound followed
step by step along it (:meth:`LearnedMargin._follow_band`), and each obstacle's margin by
where it is (:meth:`LearnedMargin.obstacle_margin`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np
import shapely
from scipy.stats import norm

from .bank import BoundBank
from .conformal import CalibratedScale, finite_margin
from .learned_data import LearnedBoundConfig, LegData, ModelFrame
from .policy import LegTracker, MarginSample
from .tube import (expanding, leg_spread, leg_tube_terms, nominal_deviation, nominal_path,
                   position_covariance)


class LearnedMargin:
    """The leg's bound and the obstacles' margins of ``learned_bound`` (a mixin).

    The state it reads and sets is :class:`.learned.LearnedBoundPolicy`'s (set up in its
    constructor; see the attributes' documentation there).
    """

    config: LearnedBoundConfig
    n: int
    m: int
    initial_margin: float | None
    cells: np.ndarray
    bank: BoundBank
    legs: LegTracker
    data: deque[LegData]
    current: LegData | None
    theta: np.ndarray | None
    sigma: np.ndarray
    region: np.ndarray
    tube: np.ndarray | None
    spread: np.ndarray | None
    whole_leg: tuple[np.ndarray, np.ndarray] | None
    cell_bound: np.ndarray | None
    corridor: np.ndarray
    path: np.ndarray | None
    path_deviation: np.ndarray
    along: np.ndarray
    along_spread: np.ndarray
    terms: np.ndarray
    along_terms: np.ndarray | None
    points: np.ndarray
    levels: np.ndarray
    radius: np.ndarray
    across: np.ndarray
    nominal: float
    recent_nominal: float
    model_margin: float
    _cell_points: shapely.Point | np.ndarray
    _local: dict[tuple[str, bytes], tuple[float, np.ndarray]]
    _prior_residual: np.ndarray
    _delta: float
    calibrated: CalibratedScale | None
    scale: float
    leg_tube: float
    leg_refuted: bool
    leg_calibrated: bool
    leg_margin: float
    _previous: np.ndarray | None

    def _follow_band(self) -> None:
        """The field's bound step by step along the current leg, and the leg's tube with it.

        docs/margins.md §5.1. At step 0 the robot is at the leg's start; if at each step j < k
        it was within radius_j of its undisturbed position, the field it met there was at most
        ℓ_j, the bound of the cells within radius_j (ceil to the bank's rungs), so at step k it
        is within radius_k = max_c Σ_j ℓ_j terms[k, j, c] / cos(π/2D) + z spread_k of it: by
        induction the levels and radii hold over the whole leg, and across its line the
        deviation is at most nominal_k + Σ_j ℓ_j along[k, j] + z along_spread_k. Without a
        leg (no model or gain yet) the bank follows the band over the region near the robot.
        """
        if self.cell_bound is None:
            return
        bound = self.cell_bound
        if self.path is None or self.tube is None or self.spread is None:
            if self.region.any():
                self.bank.evaluate(float(bound[self.region].max()))
            return
        c = self.config
        z = self._z()
        pad = c.cell * math.sqrt(0.5)   # a cell's square within the disc
        widen = 1.0 / math.cos(math.pi / (2 * c.directions))
        N = len(self.tube)
        levels = np.zeros(N + 1)
        radius = np.full(N + 1, pad)
        for k in range(N + 1):
            d = np.hypot(*(self.cells - self.points[k]).T)
            near = d <= radius[k]
            levels[k] = self.bank.ceil(float(bound[near].max())) if near.any() else 0.0
            if math.isinf(levels[k]):
                levels[k:] = math.inf
                break
            if k < N:
                radius[k + 1] = (widen * float((levels[:k + 1] @ self.terms[k, :k + 1]).max())
                                 + z * float(self.spread[k]) + pad)
        self.levels, self.radius = levels, radius
        if np.isinf(levels).any():
            self.across = np.full(N, math.inf)
        else:
            terms = (self.along_terms if self.along_terms is not None
                     else self.terms.max(axis=2) * widen)
            self.across = (self.path_deviation + np.einsum('kj,j->k', terms, levels[:N])
                           + z * self.along_spread)
        inside = np.zeros(len(self.cells), dtype=bool)
        for k in range(0, N + 1, max(N // 50, 1)):
            inside |= np.hypot(*(self.cells - self.points[k]).T) <= radius[k]
        self.corridor = inside
        self.bank.evaluate(float(levels.max()))
        self._local.clear()

    def _least_level(self, bound: np.ndarray,
                     region: Callable[[float], np.ndarray]) -> tuple[float, np.ndarray]:
        """The least rung ℓ with ceil(sup of ``bound`` over ``region(ℓ)``) <= ℓ, and its region.

        ``region`` grows with ℓ, so iterating ℓ ← ceil(sup over region(ℓ)) from ℓ = 0 rises to
        the least such rung (or to inf).
        """
        level = 0.0
        inside = region(level)
        for _ in range(200):
            higher = self.bank.ceil(float(bound[inside].max())) if inside.any() else 0.0
            if higher <= level or math.isinf(higher):
                level = max(level, higher)
                break
            level = higher
            inside = region(level)
        return level, inside

    def _new_tube(self, sample: MarginSample, state: np.ndarray | None = None) -> None:
        """The current leg under the closed loop the controller runs now (docs/margins.md §5).

        Its undisturbed path from its start state, and per step the tube (per unit level) and
        the random part's standard deviation, across the leg's line and in the worst direction
        (the latter for the corridor the field is bounded over). With ``state`` (a fit within
        the leg): the rest of the leg, from the current state on (§5.1, re-anchoring).
        """
        self.path = None
        if state is None:
            self.whole_leg = None
        if sample.gain is None or sample.horizon <= 0.0 or self.theta is None \
                or sample.leg is None or not self.legs.started:
            self.tube = None
            return
        # A leg lasts at most the horizon; the tube runs as long as the window's longest leg
        # (the horizon until a leg has ended), and a longer leg raises the margin as it goes.
        steps = max(int(round(sample.horizon / self.config.dt)), 1)
        recent = self.legs.durations[-self.config.window:]
        if recent:
            steps = min(steps, max(max(recent), 1))
        elapsed = 0 if state is None else self.legs.leg_steps
        # The rest of the leg, at least `hold_steps` (a robot held at its last target stays).
        steps = max(steps - elapsed, self.config.hold_steps) if elapsed else steps
        taus = np.maximum(sample.horizon - self.config.dt * (elapsed + np.arange(steps)), 0.0)
        gains = np.stack([np.asarray(sample.gain(float(tau)), dtype=float) for tau in taus])
        phi, gamma = self.theta[:, :self.n], self.theta[:, self.n:]
        if expanding(phi, gamma, gains):
            # The model's closed loop expands: its tube bounds nothing; the margin falls back
            # to the initial one (the running max) until a fit gives a contracting model.
            self.tube = None
            return
        offset = np.zeros((self.n, 2))
        if self.config.frame is ModelFrame.WORLD_ORIGIN:
            offset = (phi - np.eye(self.n))[:, :2]
        # D_rob is measured from the line through the leg's start and target (leg.start, as
        # the controller reports it); the replay starts from the full state at the leg start.
        start = np.asarray(self.legs.started[-1][1] if state is None else state, dtype=float)
        origin = np.asarray(sample.leg.start, dtype=float)[:2]
        target = np.asarray(sample.leg.target, dtype=float)[:2]
        line = target - origin
        length = float(np.linalg.norm(line))
        normal = np.array([-line[1], line[0]]) / length if length > 1e-12 else None
        self.terms, along_terms = leg_tube_terms(phi, gamma, gains, self._prior_residual,
                                                 normal, self.config.directions)
        self.tube = self.terms.sum(axis=1).max(axis=1) / math.cos(
            math.pi / (2 * self.config.directions))
        along = along_terms.sum(axis=1)
        # The probing of the last finished leg: it decays from leg to leg.
        source = self.data[-1] if self.data else self.current
        std, corr = source.probing_statistics(self.m) if source is not None else (0.0, 0.0)
        self.spread, along_spread = leg_spread(
            position_covariance(phi, gamma, gains, self.sigma, std, corr), normal)
        if state is None:
            self.whole_leg = (self.tube, self.spread)
        self.path, self.path_deviation = nominal_path(phi, gamma, offset, gains, start, target,
                                                      origin)
        # A zero-length leg has no line: its deviation is the distance from the target, which
        # the worst direction bounds.
        # A zero-length leg: across "its line" is any direction (the worst one's terms, the
        # widening applied when they are summed).
        self.along_terms = along_terms if normal is not None else None
        self.along = along if normal is not None else self.tube
        self.along_spread = along_spread if normal is not None else self.spread
        self.points = np.vstack([start[:2], self.path])
        self.nominal = float(self.path_deviation.max())
        starts = self.legs.started[-self.config.recent_legs:]
        self.recent_nominal = float(nominal_deviation(
            phi, gamma, offset, gains, np.array([s for _, s, _ in starts]),
            np.array([g for _, _, g in starts])).max())
        self._local.clear()

    def _z(self, tube: np.ndarray | None = None) -> float:
        # The random part must hold over the whole leg: a union bound over its steps.
        tube = self.tube if tube is None else tube
        steps = len(tube) if tube is not None else 1
        return float(norm.ppf(1.0 - 0.5 * self._delta / steps))

    def _model_margin(self) -> float:
        if self.path is None or math.isinf(self.bank.level) or len(self.across) == 0:
            return math.inf
        return float(self.across.max())

    def obstacle_margin(self, oid: str, polygon: np.ndarray) -> float:
        """The margin (m) of one obstacle by where it is (docs/margins.md §5.1).

        A prediction for the legs that will pass it: the worst-direction tube and spread at
        the least consistent level (:meth:`_least_level`) of the field within the feature
        spacing (the field's length scale) plus twice that tube of the obstacle, the
        direction and start of those legs unknown. The guarantee is the current leg's: an
        obstacle its corridor comes within the robot radius of is grown by at least the
        current leg's margin (its nominal part included), recomputed at each leg start.
        """
        key = (oid, np.ascontiguousarray(polygon, dtype=float).tobytes())
        if key not in self._local:
            shape = shapely.Polygon(polygon)
            gaps = (np.asarray(shapely.distance(shape, shapely.points(self.points)), dtype=float)
                    if self.path is not None and len(self.radius) == len(self.points)
                    else np.zeros(0))
            self._local[key] = (self._neighbourhood_margin(shape), gaps)
        generic, gaps = self._local[key]
        # The bound of the leg's motion from the last anchor on (its past deviation, which
        # the status's margin keeps, is history for the obstacles).
        now = self._now()
        if len(gaps) and np.any(gaps <= np.maximum(self.radius, now) + self.config.robot_radius):
            return max(generic, now)
        return generic

    def prior_obstacle_margin(self, oid: str, polygon: np.ndarray) -> float:
        """Calibrated, before a contracting model: the margin (m) of one obstacle (§10.1).

        The first-leg margin for an obstacle the current leg can reach -- within that margin
        and the robot radius of the leg's segment or of where the robot is -- and the
        uncalibrated fallback (``initial_margin`` or the running max) for the others: the
        legs that will pass those get their own margin when they start. (Measured: the
        first-leg margin on every obstacle shut defaults_gap's far 3.2 m gap before the robot
        had moved, 2 of 20 missions.)
        """
        margin = self._now()
        shape = shapely.Polygon(polygon)
        parts: list[shapely.Geometry] = ([] if self._previous is None
                                         else [shapely.Point(self._previous[:2])])
        leg = self.legs.leg
        if leg is not None:
            ends = np.asarray([leg.start[:2], leg.target[:2]], dtype=float)
            parts.append(shapely.LineString(ends) if np.ptp(ends, axis=0).any()
                         else shapely.Point(ends[0]))
        near = not parts or min(shape.distance(p) for p in parts) \
            <= margin + self.config.robot_radius
        return margin if near else min(margin, self._fallback())

    def _neighbourhood_margin(self, shape: shapely.Polygon) -> float:
        if self.cell_bound is None or self.tube is None or self.whole_leg is None:
            return max(self._margin(), self.legs.leg_max)
        tube, spread = self.whole_leg
        z = self._z(tube)
        dist = np.asarray(shapely.distance(shape, self._cell_points), dtype=float)
        scale = self.config.feature_spacing
        pad = self.config.cell * math.sqrt(0.5)
        level, _ = self._least_level(
            self.cell_bound,
            lambda lv: np.asarray(dist <= scale + 2.0 * float((lv * tube + z * spread).max())
                                  + pad))
        if math.isinf(level):
            return max(self._margin(), self.legs.leg_max)
        # No nominal part: how a future leg is entered (its start velocity against its line)
        # is known when it starts, and then its own margin grows the obstacles near it.
        return float((level * tube + z * spread).max()) * self._far_scale(level)

    def _far_scale(self, level: float) -> float:
        """Calibrated: the factor on a far obstacle's prediction -- at most 1 (§10.1).

        The scale of the category a leg passing it would start in (refuted where the level
        there is above 1) where that is below 1: the calibration measured that such legs'
        tubes are that conservative. Never above 1: the prediction is the current leg's tube
        carried elsewhere, and a scale earned by unlearned fields multiplied it too far
        (scaled by 2.2, bump_mid's far gap shut in 7 of 20 missions); the leg that passes
        the obstacle is grown by its own calibrated margin when it starts.
        """
        if self.calibrated is None:
            return 1.0
        scale, _ = self.calibrated.leg_scale(level > 1.0)
        return 1.0 if scale is None else min(1.0, scale)

    def _fallback(self) -> float:
        return self.legs.d_rob_max if self.initial_margin is None else self.initial_margin

    def _margin(self) -> float:
        if math.isinf(self.model_margin):
            prior = self._prior_margin()
            return self._fallback() if prior is None else prior
        return self.scale * self.model_margin

    def _now(self) -> float:
        """The margin in force now: calibrated, never below the leg's (its scores' premise)."""
        if self.calibrated is None:
            return self._margin()
        return max(self.leg_margin, self._margin())

    def _prior_margin(self) -> float | None:
        """Calibrated: m, the margin of a leg without a model (None: no calibration yet)."""
        return None if self.calibrated is None else finite_margin(self.calibrated.prior)

    def _calibrate(self) -> None:
        """At a leg's start: the leg's tube and category, and calibrated its scale (§10).

        The category: whether the tube rests on a level above the prior bound R, one that
        residuals within reach of the leg raised (the cells' bound is at most 1 elsewhere).
        """
        self.leg_tube = self.model_margin if math.isfinite(self.model_margin) else 0.0
        self.leg_refuted = self.leg_tube > 0.0 and self.bank.level > 1.0
        if self.calibrated is None:
            return
        if self.leg_tube > 0.0:
            scale, self.leg_calibrated = self.calibrated.leg_scale(self.leg_refuted)
        else:
            scale, self.leg_calibrated = None, self._prior_margin() is not None
        self.scale = 1.0 if scale is None else scale   # None: no calibration yet, the bound
