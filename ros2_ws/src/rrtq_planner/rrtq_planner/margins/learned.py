"""``learned_bound``: Jha's data-driven bound, turned into a margin through the closed loop.

Per step (``docs/margins.md`` §3-5.1): the pair (x̄_{k−1}, u_{k−1}) → x̄_k joins the sufficient
statistics of the current leg, with the features φ(p_{k−1}) of where the residual acted; a
residual on the velocity rows above the prior bound R (plus the noise allowance) counts
against R in the cells near it, and three such residuals refute R there (up at once).

At each leg start and every ``evaluation_period``: the one-step model x̄_{k+1} ≈ Φ̂x̄_k + Γ̂u_k
and the residual's field over the plane are fitted together on the last ``window`` legs
(:func:`.regression.fit_field` with a model block: least squares, as a recursive fit would
give, but kept as per-leg statistics so that old legs can leave the window, and joint so
that the linear model cannot soak up the field), and the refutations are recomputed against
it. Each cell's bound is the upper band capped by R, or the residuals where R is refuted.
Then the current leg (from its start, or from the current state within it) is bounded step
by step along its undisturbed path under the controller's current gain: the field's level at
each step is the cells' bound within the radius the robot can be at, the radius follows
from the levels before (an induction over the steps), and the margin is the deviation across
the leg's line. Each obstacle is grown by the margin of where it is
(:meth:`LearnedBoundPolicy.obstacle_margin`).

This module learns (the statistics, the fits, the refutations); turning the fit into the
leg's tube and the margins is :mod:`.learned_margin`'s, and the settings and data types are
:mod:`.learned_data`'s.

With a :class:`.conformal.CalibratedScale` (``safety.conformal``, docs/margins.md §10) the
bound is conformalized: each leg is scored by its largest deviation over the tube predicted
at its start, and a leg's margin is that tube times the conformal quantile of the scores
(or, for a leg that starts without a contracting model, the quantile of such legs' raw
deviations); the margin in force for a leg never drops within it.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import shapely

from .bank import BoundBank
from .conformal import CalibratedScale
from .learned_data import Bounds, FieldEstimate, LearnedBoundConfig, LegData, ModelFrame
from .learned_margin import LearnedMargin
from .policy import LegTracker, MarginMode, MarginSample, MarginStatus
from .regression import FieldFit, RBFFeatures, fit_field

__all__ = ['Bounds', 'ModelFrame', 'LearnedBoundConfig', 'LearnedBoundPolicy', 'FieldEstimate']


class LearnedBoundPolicy(LearnedMargin):
    """Margin from a learned residual bound through the current closed loop.

    Parameters
    ----------
    config
        See :class:`LearnedBoundConfig`.
    n, m
        State and input dimensions.
    initial_margin
        m, the margin while the bank has no finite level; None: the running max of D_rob.
    calibrated
        The conformal calibration of the scale (docs/margins.md §10); None: the bound as it
        is (``safety.conformal: false``).
    """

    mode = MarginMode.LEARNED_BOUND

    def __init__(self, config: LearnedBoundConfig, n: int = 4, m: int = 2,
                 initial_margin: float | None = None,
                 calibrated: CalibratedScale | None = None) -> None:
        self.config = config
        self.calibrated = calibrated
        self.scale = 1.0
        """The factor on the predicted tube (1 without calibration or before it certifies)."""
        self.leg_tube = 0.0
        """m, the current leg's uncalibrated prediction at its start (0: no model then)."""
        self.leg_refuted = False
        """Whether the current leg's tube rests on a level residuals raised above R."""
        self.leg_calibrated = False
        """Whether the current leg's margin came from its category's quantile (ACI adapts)."""
        self.n, self.m, self.d = n, m, n + m
        self.initial_margin = initial_margin
        self.features = RBFFeatures(config.region, config.feature_spacing)
        (x0, x1), (y0, y1) = config.region
        self._nx = int(math.floor((x1 - x0) / config.cell)) + 1
        self._ny = int(math.floor((y1 - y0) / config.cell)) + 1
        gx, gy = np.meshgrid(x0 + config.cell * np.arange(self._nx),
                             y0 + config.cell * np.arange(self._ny), indexing='ij')
        self.cells = np.column_stack([gx.ravel(), gy.ravel()])
        self._cell_phi = self.features(self.cells)
        r = int(math.ceil(config.reach / config.cell))
        di, dj = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1), indexing='ij')
        keep = np.hypot(di, dj) * config.cell <= config.reach
        self._stencil = np.column_stack([di[keep], dj[keep]])
        self._prior = (np.hstack([np.eye(n), np.zeros((n, m))]), config.model_prior_precision)
        self._prior_residual = np.full(n, config.prior_bound * config.dt)
        self._prior_residual[:2] = 0.5 * config.prior_bound * config.dt**2
        self.bank = BoundBank(config.bank_ratio)
        self.legs = LegTracker()
        self.data: deque[LegData] = deque(maxlen=config.window)
        self.current: LegData | None = None
        self.theta: np.ndarray | None = None
        """Θ̂ = [Φ̂ | Γ̂] (n, n + m) of the last fit; None before the first."""
        self.sigma = np.full(n, config.noise_floor)
        self.fit: FieldFit | None = None
        """The last fit of the residual's field (for ``/safety/disturbance_estimate``)."""
        self.region = np.zeros(len(self.cells), dtype=bool)
        """Cells the band's supremum was last taken over (visited, near the robot)."""
        self.tube: np.ndarray | None = None
        """Worst-case deviation per unit bound over a leg (:func:`.tube.tube_gains`)."""
        self.spread: np.ndarray | None = None
        """Standard deviation of the random deviation over a leg (:func:`.tube.random_deviation`)."""
        self.whole_leg: tuple[np.ndarray, np.ndarray] | None = None
        """(tube, spread) of the current leg from its start: the far obstacles' prediction for
        a whole future leg, which a fit within the leg (re-anchored over the rest of it) must
        not shorten (docs/margins.md §9: the livelock)."""
        self.cell_bound: np.ndarray | None = None
        """Per cell, the bound of the field in units of R (max over components) after the last
        fit: min(upper band, 1), or max(upper band, residual) where a residual refuted R."""
        self.corridor = np.zeros(len(self.cells), dtype=bool)
        """Cells the current leg's level was last taken over (its corridor, §5)."""
        self.path: np.ndarray | None = None
        """The current leg's undisturbed positions (N, 2) under the model."""
        self.path_deviation = np.zeros(0)
        self.along = np.zeros(0)
        """Tube across the current leg's line per unit level (N,)."""
        self.along_spread = np.zeros(0)
        self.terms = np.zeros((0, 0, config.directions))
        """The tube's terms [k, j, direction] (:func:`.tube.leg_tube_terms`)."""
        self.along_terms: np.ndarray | None = None
        self.points = np.zeros((0, 2))
        """The undisturbed positions at steps 0..N of the current leg (its start first)."""
        self.levels = np.zeros(0)
        """The field's bound (units of R) the robot can meet at each step of the leg."""
        self.radius = np.zeros(0)
        """m, how far from its undisturbed position the robot can be at each step."""
        self.across = np.zeros(0)
        """m, the bound on the deviation from the leg's line at steps 1..N."""
        self._top = np.zeros((len(self.cells), 3))
        self.observed = np.zeros(len(self.cells))
        """Per cell, the third largest residual (net of the noise allowance, in units of R)
        taken within ``reach`` of it: above 1 it refutes the prior bound there (up at once on
        evidence, three residuals so that one outlier does not) and is a floor of the cell's
        bound."""
        self._cell_points = shapely.points(self.cells)
        self._local: dict[tuple[str, bytes], tuple[float, np.ndarray]] = {}
        self.nominal = 0.0
        self.recent_nominal = 0.0
        """Largest nominal deviation of the recent legs' starts under the current loop."""
        self.model_margin = math.inf
        self.leg_margin = self._margin()
        self.last_fit = -math.inf
        self.fits = 0
        """Fits made so far (the node publishes an estimate when it changes)."""
        self._cell_band: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.flagged = False
        self.misses = 0
        self._delta = 1.0 - config.confidence
        self._previous: np.ndarray | None = None   # x_{k−1}, world frame

    # ------------------------------------------------------------------ interface
    @property
    def scores(self) -> list[float]:
        return self.legs.scores

    @property
    def samples(self) -> int:
        """Residual samples in the window."""
        return sum(d.count for d in self.data) + (self.current.count if self.current else 0)

    def step(self, sample: MarginSample) -> MarginStatus:
        c = self.config
        state = np.asarray(sample.state, dtype=float)
        ended = self.legs.update(sample)
        if ended is not None:
            self.misses += ended > self.leg_margin
            if self.calibrated is not None:
                self.calibrated.observe(ended, self.leg_tube, self.leg_margin,
                                        self.leg_calibrated, self.leg_refuted)
        if self.legs.new_leg:
            if self.current is not None:
                self.data.append(self.current)
            self.current = LegData(self.features.size, self.n, self.d, len(self.cells))
        raised = self._learn(state, sample)
        if self.legs.new_leg:
            self._fit(sample.t, state)
            self._new_tube(sample)
            self._follow_band()
            self.model_margin = self._model_margin()
            self._calibrate()
            self.leg_margin = self._margin()
            self.flagged = False
        elif sample.t - self.last_fit >= c.evaluation_period - 1e-9 and self.current is not None:
            self._fit(sample.t, state)
            self._new_tube(sample, state)
            self._follow_band()
            self.model_margin = self._model_margin()
        elif raised:
            self.model_margin = self._model_margin()
        t = self.legs
        violation = t.leg is not None and t.leg_max > self.leg_margin and not self.flagged
        self.flagged |= violation
        local = (self.obstacle_margin if math.isfinite(self.model_margin)
                 else self.prior_obstacle_margin if self._prior_margin() is not None else None)
        return MarginStatus(self.mode, max(self._now(), t.leg_max), self.leg_margin,
                            self.bank.level * c.prior_bound, c.confidence, self.samples,
                            self.misses + self.flagged, t.d_rob, t.d_rob_max, violation,
                            self.bank.violations, t.leg_max, t.count, local,
                            leg_tube=self.leg_tube, scale=self.scale,
                            leg_refuted=self.leg_refuted)

    def estimate(self) -> FieldEstimate | None:
        """The last fit's field and band as accelerations on the cells; None before a fit."""
        if self._cell_band is None:
            return None
        c = self.config
        mean, half, supported = self._cell_band
        (x0, _), (y0, _) = c.region
        return FieldEstimate(self.last_fit, (x0, y0), c.cell, (self._nx, self._ny),
                             mean[:, 2:4] / c.dt, half[:, 2:4] / c.dt, supported.copy(),
                             self.bank.level * c.prior_bound, c.confidence, self.samples)

    # ------------------------------------------------------------------ learning
    def _learn(self, state: np.ndarray, sample: MarginSample) -> bool:
        """Account the pair (x̄_{k−1}, u_{k−1}) → x̄_k; True when its residual raised the bank.

        The pair is taken in the frame of the leg that issued u_{k−1} (``sample.leg``); the
        residual is attributed to p_{k−1}, where it acted.
        """
        prev, self._previous = self._previous, state.copy()
        leg = sample.leg
        if prev is None or leg is None or leg.d0 <= 0.0 or sample.applied is None \
                or self.current is None:
            return False
        if sample.probing is not None:
            self.current.add_probing(np.asarray(sample.probing, dtype=float))
        xr = np.zeros(self.n)
        if self.config.frame is ModelFrame.LEG_TARGET:
            xr[:2] = np.asarray(leg.target, dtype=float)[:2]
        z = np.concatenate([prev - xr, np.asarray(sample.applied, dtype=float)])
        y = state - xr
        self.current.stats.add(self.features(prev[:2]), y, z)
        near = self._visit(prev[:2])
        if self.legs.leg_steps > 2:
            self.current.samples.append((z, y, self._cell_of(prev[:2])))
        if self.theta is None:
            return False
        excess = np.abs(y - self.theta @ z) - self.config.noise_allowance * self.sigma
        level = float((excess / self._prior_residual).max())
        raised = self.bank.observe(level)
        # The field acts on the velocity rows (E = [0; I]); on the position rows, where its
        # share is R dt²/2, a residual measures the model's own error, and refutes nothing.
        level = float((excess / self._prior_residual)[2:4].max())
        if self.legs.leg_steps <= 2:
            # A leg change moves the rover's spring anchor within a step of the controller's
            # state: the first residuals of a leg mix two frames and refute nothing.
            return raised
        if level <= 0.0:
            return raised
        top = np.sort(np.column_stack([self._top[near], np.full(len(near), level)]), axis=1)
        self._top[near] = top[:, :0:-1]
        self.observed[near] = self._top[near, 2]
        third = self.observed[near]
        if self.cell_bound is not None and bool(((third > 1.0)
                                                 & (self.cell_bound[near] < third)).any()):
            # Up at once on evidence: the prior is refuted here; the leg's levels follow.
            self.cell_bound[near] = np.where(third > 1.0, np.maximum(self.cell_bound[near],
                                                                     third),
                                             self.cell_bound[near])
            self._follow_band()
            raised = True
        return raised

    def _cell_of(self, p: np.ndarray) -> int:
        (x0, _), (y0, _) = self.config.region
        i = min(max(int(round((p[0] - x0) / self.config.cell)), 0), self._nx - 1)
        j = min(max(int(round((p[1] - y0) / self.config.cell)), 0), self._ny - 1)
        return i * self._ny + j

    def _refutations(self, blocks: list[LegData]) -> None:
        """Recompute every cell's three largest residuals against the model just fitted.

        Residuals of an early, poorly excited model must not refute the prior for good
        (measured: three of 21 m/s² at one place on narrow_gap's first legs).
        """
        rows = [r for b in blocks for r in b.samples]
        self._top = np.zeros((len(self.cells), 3))
        if not rows or self.theta is None:
            self.observed = self._top[:, 2].copy()
            return
        z = np.array([r[0] for r in rows])
        y = np.array([r[1] for r in rows])
        cell = np.array([r[2] for r in rows])
        excess = np.abs(y - z @ self.theta.T) - self.config.noise_allowance * self.sigma
        level = (excess / self._prior_residual)[:, 2:4].max(axis=1)
        keep = level > 0.0
        if keep.any():
            i, j = np.divmod(cell[keep], self._ny)
            ii = i[:, None] + self._stencil[None, :, 0]
            jj = j[:, None] + self._stencil[None, :, 1]
            ok = (ii >= 0) & (ii < self._nx) & (jj >= 0) & (jj < self._ny)
            cells = (ii * self._ny + jj)[ok]
            values = np.broadcast_to(level[keep][:, None], ok.shape)[ok]
            order = np.lexsort((-values, cells))
            cells, values = cells[order], values[order]
            first = np.r_[0, np.flatnonzero(np.diff(cells)) + 1]
            rank = np.arange(len(cells)) - np.repeat(first, np.diff(np.r_[first, len(cells)]))
            top = rank < 3
            self._top[cells[top], rank[top]] = values[top]
        self.observed = self._top[:, 2].copy()

    def _visit(self, p: np.ndarray) -> np.ndarray:
        """Mark the cells within ``reach`` of p visited; returns their indices."""
        (x0, _), (y0, _) = self.config.region
        ij = np.rint([(p[0] - x0) / self.config.cell, (p[1] - y0) / self.config.cell]).astype(int)
        idx = ij[None] + self._stencil
        ok = (idx[:, 0] >= 0) & (idx[:, 0] < self._nx) & (idx[:, 1] >= 0) & (idx[:, 1] < self._ny)
        assert self.current is not None
        flat = idx[ok, 0] * self._ny + idx[ok, 1]
        self.current.visited[flat] = True
        return flat

    def _fit(self, t: float, state: np.ndarray) -> None:
        """Fit model and field on the window; the bank follows the band near the robot."""
        self.last_fit = t
        blocks = [b for b in (*self.data, self.current) if b is not None and b.count]
        if sum(b.count for b in blocks) <= self.d:
            return
        stats = blocks[0].stats
        for b in blocks[1:]:
            stats = stats + b.stats
        c = self.config
        fit = fit_field(stats, c.ridge, self._delta, 0.0, c.noise_floor, model_prior=self._prior)
        # S_c, the norm of the true weights, is an assumption the data cannot check
        # (docs/margins.md): the fitted norm, at least the prior bound, times a factor.
        # (The fitted norm alone fails early: on one leg the model soaks up the field.)
        s = np.maximum(np.linalg.norm(fit.weights, axis=0), self._prior_residual)
        fit = fit.with_weight_bound(c.weight_bound * s)
        self.fit, self.theta, self.sigma = fit, fit.model, fit.sigma
        self._refutations(blocks)
        reach = 2.0 * max([d0 for d0 in self._leg_lengths()] + [c.feature_spacing])
        near = np.hypot(*(self.cells - state[:2]).T) <= reach
        visited = np.logical_or.reduce([b.visited for b in blocks])
        # ‖φ‖_{V⁻¹} of every cell, once per fit: the band, and where the data support it.
        spread = fit.spread(self._cell_phi)
        firm = math.sqrt(c.ridge) * spread <= c.support
        self.region = near & visited & firm
        # The bound of every cell, in units of the prior bound (|d_i| <= level R_i for every
        # component): the upper band, capped by the prior bound R (Jha's assumption 3.1: the
        # minimum of two bounds, each valid under its assumption) -- except where a residual
        # has exceeded R (net of the noise allowance) within `reach`: there the assumption is
        # refuted and, as in Jha's Alg. 1, the bound is raised to the largest such residual
        # (the band, which would certify it, is confounded with the model along a straight
        # route: docs/margins.md §5.1).
        mean, half = fit.band(self._cell_phi, spread)
        upper = ((np.abs(mean) + half) / self._prior_residual).max(axis=1)
        refuted = self.observed > 1.0
        self.cell_bound = np.where(refuted, self.observed, np.minimum(upper, 1.0))
        self._cell_band = (mean, half, firm & visited)
        self.fits += 1

    def _leg_lengths(self) -> list[float]:
        return [float(np.linalg.norm(s[:2] - g)) for _, s, g in
                self.legs.started[-(self.config.window + 1):]]
