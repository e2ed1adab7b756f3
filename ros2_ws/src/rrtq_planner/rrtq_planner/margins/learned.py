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
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import deque
from collections.abc import Callable

import numpy as np
import shapely
from scipy.stats import norm

from rrtq_common.settings import check, setting

from .bank import BoundBank
from .policy import LegTracker, MarginMode, MarginSample, MarginStatus
from .regression import FieldFit, FieldStatistics, RBFFeatures, fit_field
from .tube import (expanding, leg_spread, leg_tube_terms, nominal_deviation, nominal_path,
                   position_covariance)

__all__ = ['ModelFrame', 'LearnedBoundConfig', 'LearnedBoundPolicy', 'FieldEstimate']

Bounds = tuple[tuple[float, float], tuple[float, float]]


class ModelFrame(enum.StrEnum):
    """Where the observer's one-step model is time-invariant (the rover's spring anchor)."""

    LEG_TARGET = 'leg_target'
    """x̄ relative to the current leg's target at rest."""
    WORLD_ORIGIN = 'world_origin'
    """x̄ = x."""


@dataclasses.dataclass(frozen=True)
class LearnedBoundConfig:
    """Parameters of ``learned_bound`` (each a :func:`rrtq_common.settings.setting`)."""

    region: Bounds = setting(unit='m', doc="((x_min, x_max), (y_min, y_max)): where the field "
                             "is learned (the scenario's bounds)")
    dt: float = setting(unit='s', low=0.0, low_open=True,
                        doc="the step of the loop (the controller's tau grid over a leg)")
    frame: ModelFrame = setting(ModelFrame.LEG_TARGET, doc='frame of the one-step model: '
                                'plant.spring_anchor (either without a spring)')
    confidence: float = setting(0.95, low=0.0, high=1.0, low_open=True, high_open=True,
                                doc='1 - delta of the simultaneous band (and of the noise '
                                'part of the tube)')
    window: int = setting(50, low=1, doc='legs of residual data the field is fitted on')
    feature_spacing: float = setting(
        2.0, unit='m', low=0.0, low_open=True,
        doc='spacing and length scale of the radial basis functions: at most the length '
        "scale of the field, or what they cannot fit leaks into the model's coefficients "
        '(docs/margins.md, section 4.2: at 4 m a 3 m bump softened the learned loop 3x)')
    ridge: float = setting(1.0, low=0.0, low_open=True,
                           doc='lambda of the regression (the features are of order 1)')
    prior_bound: float = setting(
        0.1, unit='m/s^2', low=0.0, low_open=True,
        doc='R: the field strength assumed possible before the data say otherwise (Jha\'s '
        'assumption 3.1); per component of the residual R dt on velocities, R dt^2/2 on '
        'positions')
    weight_bound: float = setting(1.5, low=0.0, low_open=True,
                                  doc="S_c = this x max(|w_c|, R_c): the bound of the field's "
                                  'weight norm the band assumes')
    noise_floor: float = setting(1e-5, low=0.0, low_open=True, doc='lower bound of the '
                                 'residual noise sigma_c, state units per step')
    cell: float = setting(1.0, unit='m', low=0.0, low_open=True,
                          doc="spacing of the cells the band's supremum is taken over")
    reach: float = setting(1.0, unit='m', low=0.0, low_open=True,
                           doc='a cell counts as visited when a residual was taken within '
                           'this distance')
    support: float = setting(
        0.5, low=0.0, low_open=True,
        doc="the band's supremum is taken over the visited cells within twice the longest "
        'leg of the window (at least twice feature_spacing) of the robot where the data have '
        "cut the band's width to at most this fraction of the prior's: where the next legs "
        'go and the data say something; elsewhere the bound is extrapolated, and a residual '
        'above it raises it at once (docs/margins.md, section 3)')
    bank_ratio: float = setting(0.8, doc='ratio of neighbouring levels of the bank')
    noise_allowance: float = setting(4.0, doc='a residual raises the bank when a component '
                                     'exceeds its bound by this many sigma_i')
    model_prior_precision: float = setting(1e-6, low=0.0, low_open=True,
                                           doc="mu: precision of the model's prior Phi = I, "
                                           'Gamma = 0 (negligible against a leg of data)')
    evaluation_period: float = setting(2.0, unit='s', low=0.0, low_open=True,
                                       doc='between fits within a leg (a fit also ends every '
                                       'leg)')
    recent_legs: int = setting(10, low=1, doc='leg starts (the last ones, the current '
                               'included) replayed through the current closed loop for the '
                               'nominal part: how the robot enters its legs now, not during '
                               'a transient')
    directions: int = setting(16, doc="directions of a leg's normal the tube is maximised over")
    robot_radius: float = setting(0.5, unit='m', low=0.0, doc='an obstacle within this of the '
                                  "current leg's corridor is grown by that leg's margin")
    hold_steps: int = setting(40, low=1, doc='steps the rest of a leg is bounded over at least '
                              'when a fit within it re-anchors the tube')

    def __post_init__(self) -> None:
        check(self, finite=True)


@dataclasses.dataclass(frozen=True)
class FieldEstimate:
    """The last fit's field and band on the policy's cells (``/safety/disturbance_estimate``).

    Accelerations (m/s²): the residual's velocity rows divided by dt. Cell k is at
    ``cells[k]``, on a grid of ``shape`` (nx, ny) from ``origin`` at ``spacing``, k = i ny + j.
    """

    t: float
    """s, when the fit was made."""
    origin: tuple[float, float]
    spacing: float
    shape: tuple[int, int]
    mean: np.ndarray
    """(cells, 2): the fitted field."""
    band: np.ndarray
    """(cells, 2): half-width of the simultaneous band."""
    supported: np.ndarray
    """(cells,): visited within reach, band cut to at most ``support`` of the prior's."""
    bound: float
    """m/s², the bank's level as an acceleration."""
    confidence: float
    samples: int


class _LegData:
    """One leg's samples: statistics for the joint fit, visited cells, probing moments."""

    def __init__(self, p: int, n: int, d: int, cells: int) -> None:
        self.stats = FieldStatistics.zeros(p, n, d)
        self.visited = np.zeros(cells, dtype=bool)
        self.probing = np.zeros(3)            # Σ‖p‖², Σ p_k·p_{k−1}, pairs
        self._last_probe: np.ndarray | None = None
        self.samples: list[tuple[np.ndarray, np.ndarray, int]] = []
        """(z, y, cell) of the leg's samples past its first steps: residuals are recomputed
        against every new fit (docs/margins.md §5.1)."""

    @property
    def count(self) -> int:
        return self.stats.count

    def add_probing(self, p: np.ndarray) -> None:
        lag = 0.0 if self._last_probe is None else float(p @ self._last_probe)
        self.probing += (float(p @ p), lag, float(self._last_probe is not None))
        self._last_probe = p.copy()

    def probing_statistics(self, m: int) -> tuple[float, float]:
        """(stationary std per component, N; lag-one correlation) of the leg's probing."""
        sq, lag, pairs = self.probing
        if pairs < 2 or sq <= 0.0:
            return 0.0, 0.0
        steps = pairs + 1
        return math.sqrt(sq / (steps * m)), min(max(lag / sq * steps / pairs, 0.0), 0.999)


class LearnedBoundPolicy:
    """Margin from a learned residual bound through the current closed loop.

    Parameters
    ----------
    config
        See :class:`LearnedBoundConfig`.
    n, m
        State and input dimensions.
    initial_margin
        m, the margin while the bank has no finite level; None: the running max of D_rob.
    """

    mode = MarginMode.LEARNED_BOUND

    def __init__(self, config: LearnedBoundConfig, n: int = 4, m: int = 2,
                 initial_margin: float | None = None) -> None:
        self.config = config
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
        self.data: deque[_LegData] = deque(maxlen=config.window)
        self.current: _LegData | None = None
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
        if self.legs.new_leg:
            if self.current is not None:
                self.data.append(self.current)
            self.current = _LegData(self.features.size, self.n, self.d, len(self.cells))
        raised = self._learn(state, sample)
        if self.legs.new_leg:
            self._fit(sample.t, state)
            self._new_tube(sample)
            self._follow_band()
            self.model_margin = self._model_margin()
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
        local = None if math.isinf(self.model_margin) else self.obstacle_margin
        return MarginStatus(self.mode, max(self._margin(), t.leg_max), self.leg_margin,
                            self.bank.level * c.prior_bound, c.confidence, self.samples,
                            self.misses + self.flagged, t.d_rob, t.d_rob_max, violation,
                            self.bank.violations, t.leg_max, t.count, local)

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

    def _refutations(self, blocks: list[_LegData]) -> None:
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

    def _leg_lengths(self) -> list[float]:
        return [float(np.linalg.norm(s[:2] - g)) for _, s, g in
                self.legs.started[-(self.config.window + 1):]]

    # ------------------------------------------------------------------ margin
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
        now = self._margin()
        if len(gaps) and np.any(gaps <= np.maximum(self.radius, now) + self.config.robot_radius):
            return max(generic, now)
        return generic

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
        return float((level * tube + z * spread).max())

    def _fallback(self) -> float:
        return self.legs.d_rob_max if self.initial_margin is None else self.initial_margin

    def _margin(self) -> float:
        return self._fallback() if math.isinf(self.model_margin) else self.model_margin
