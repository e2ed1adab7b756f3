"""Split-conformal margin over leg scores, plain and adaptive (``docs/margins.md`` §2).

A leg's score is its largest deviation D_rob from its straight edge (RRT-QX eq. 6). With
the last n scores of a window, the ⌈(n+1)(1−δ)⌉-th smallest is a margin the next score
stays under with probability at least 1 − δ when the scores are exchangeable (split
conformal prediction: Vovk et al. 2005; Lei et al. 2018, Theorem 2.1). The controller keeps
learning, so scores drift and are not exchangeable; the adaptive form (adaptive conformal
inference, Gibbs & Candès 2021) moves the level δ_t after each leg,

    δ_{t+1} = δ_t + η (δ − miss_t),     miss_t = 1 if score_t > margin_t,

which keeps the long-run miss rate within (max(δ, 1 − δ) + η) / (η T) of δ over any T
legs, whatever the scores do (their Proposition 4.1). η = 0 is the plain form.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Iterable

import numpy as np
import numpy.typing as npt

from rrtq_common.settings import check, setting

__all__ = ['ConformalConfig', 'ConformalQuantile', 'CalibratedScale', 'conformal_rank',
           'conformal_quantile', 'minimum_scores', 'aci_miss_rate_bound', 'finite_margin']


def conformal_rank(n: int, delta: float) -> int:
    """⌈(n + 1)(1 − δ)⌉: the rank (1-based, ascending) of the conformal quantile of n scores."""
    # The product is exact for the usual δ; the guard keeps 0.95 * 20 = 19.000000000000004
    # from rounding up to 20.
    return math.ceil((n + 1) * (1.0 - delta) - 1e-9)


def minimum_scores(delta: float) -> int:
    """⌈1/δ⌉ − 1: the fewest scores for which the conformal quantile at level δ is finite."""
    return math.ceil(1.0 / delta - 1e-9) - 1


def conformal_quantile(scores: npt.ArrayLike, delta: float) -> float:
    """The ⌈(n+1)(1−δ)⌉-th smallest of the n scores.

    +inf when that rank exceeds n (too few scores to certify 1 − δ: the conformal set is
    everything), 0 when it is below 1 (δ ≥ 1: the empty set; scores are ≥ 0).
    """
    s = np.asarray(scores, dtype=float).reshape(-1)
    rank = conformal_rank(s.size, delta)
    if rank > s.size:
        return math.inf
    if rank < 1:
        return 0.0
    return float(np.partition(s, rank - 1)[rank - 1])


def aci_miss_rate_bound(delta: float, eta: float, legs: int) -> float:
    """|miss rate − δ| over ``legs`` legs is at most this for the adaptive form (η > 0)."""
    return (max(delta, 1.0 - delta) + eta) / (eta * legs)


@dataclasses.dataclass(frozen=True)
class ConformalConfig:
    """Parameters of the conformal margin (each a :func:`rrtq_common.settings.setting`)."""

    confidence: float = setting(0.95, low=0.0, high=1.0, low_open=True, high_open=True,
                                doc="1 - delta: the probability with which the next leg's "
                                'score stays under the margin')
    window: int = setting(50, low=1, doc='legs kept: the margin is a quantile of the last '
                          'window scores')
    adaptation: float = setting(0.05, low=0.0, doc='eta, the step of the adaptive level '
                                'delta_t per leg; 0 gives the plain form')

    def __post_init__(self) -> None:
        check(self, finite=True)

    @property
    def delta(self) -> float:
        """δ = 1 − confidence."""
        return 1.0 - self.confidence


class ConformalQuantile:
    """The window of leg scores, the adaptive level δ_t and the misses.

    Parameters
    ----------
    config
        Confidence, window, adaptation.
    calibration
        Scores of earlier runs (oldest first): they fill the window before this run's own.
    """

    def __init__(self, config: ConformalConfig, calibration: Iterable[float] = ()) -> None:
        self.config = config
        self.scores: deque[float] = deque(maxlen=config.window)
        for s in calibration:
            self.scores.append(float(s))
        self.delta_t = config.delta
        self.legs = 0
        self.misses = 0

    @property
    def level(self) -> float:
        """1 − δ_t, clipped to [0, 1]: the confidence the current quantile is taken at."""
        return min(max(1.0 - self.delta_t, 0.0), 1.0)

    @property
    def margin(self) -> float:
        """The conformal quantile of the window at δ_t, m (+inf: not enough scores)."""
        return conformal_quantile(np.fromiter(self.scores, float, len(self.scores)),
                                  self.delta_t)

    @property
    def warming_up(self) -> bool:
        """Fewer scores than the plain quantile at δ needs (⌈1/δ⌉ − 1): no prediction yet."""
        return len(self.scores) < minimum_scores(self.config.delta)

    def observe(self, score: float, margin_used: float, adapt: bool = True) -> bool:
        """Account a finished leg: its score, and the margin that was in force for it.

        Returns True when the score exceeded that margin (a miss); the level δ_t then moves
        by the adaptive step (``adapt``), and the score joins the window. ``adapt=False``
        for a leg of the warm-up (:attr:`warming_up` at its start): its margin was not this
        quantile's prediction, and an infinite set's "coverage" must not buy the later
        quantiles a lower level (δ_t would rise by ηδ per warm-up leg and the first finite
        quantile come at 1 − δ_t < 1 − δ).
        """
        miss = bool(score > margin_used)
        self.legs += 1
        self.misses += miss
        if adapt:
            self.delta_t += self.config.adaptation * (self.config.delta - miss)
        self.scores.append(float(score))
        return miss


def finite_margin(quantile: ConformalQuantile, floor: float = 0.0) -> float | None:
    """The quantile's margin, finite, or None while it warms up.

    When misses have pushed δ_t under 1/(n + 1) the conformal set is everything; the
    largest score seen (at least ``floor``) stands in for it.
    """
    q = quantile.margin
    if math.isfinite(q):
        return q
    if quantile.warming_up:
        return None
    return max(floor, max(quantile.scores))


class CalibratedScale:
    """``learned_bound``'s conformal calibration: three Mondrian categories (docs/margins.md §10).

    A leg that starts with a contracting model is scored by its largest deviation over the
    tube ``learned_bound`` predicted for it at its start (normalized, locally adaptive
    conformal scores: Papadopoulos et al. 2008, Lei et al. 2018 §5.2); its margin is that
    tube times the conformal quantile of the scores, the *scale*. Those legs fall in two
    categories by the level their tube rests on: the prior bound R, unrefuted along the leg
    (a miss there is a field the data had not shown: a bump entered), or a level residuals
    raised above R (a field already met, bounded by what was measured). A leg that starts
    without a model (a mission's first legs) has no tube: it is scored raw, in m, and its
    margin is the conformal quantile of those. Each category has its own window and adaptive
    level δ_t (Mondrian conformal prediction, Vovk et al. 2005 §4.5: the guarantee holds
    within each category, so over all legs too). A refuted leg whose category cannot certify
    1 − δ yet takes the quantile of both model categories' scores together (the two-category
    calibration), and its score does not move its category's level.

    Parameters
    ----------
    config
        Confidence, window (legs of this run kept beside the calibration), adaptation.
    normalized, prior, refuted
        The categories' scores of earlier runs (:mod:`.calibration`), oldest first: all of
        them are kept, and this run's last ``window`` legs with them.
    """

    def __init__(self, config: ConformalConfig, normalized: Iterable[float] = (),
                 prior: Iterable[float] = (), refuted: Iterable[float] = ()) -> None:
        def category(scores: Iterable[float]) -> ConformalQuantile:
            kept = list(scores)
            return ConformalQuantile(
                dataclasses.replace(config, window=config.window + len(kept)), kept)

        self.model = category(normalized)
        """Legs whose tube rests on the prior bound R (the bank's level at most 1)."""
        self.refuted = category(refuted)
        """Legs whose tube rests on a level residuals raised above R."""
        self.prior = category(prior)
        """Legs without a contracting model at their start (scored raw, m)."""

    @property
    def scale(self) -> float:
        """The factor on a tube at the prior bound; +inf while it cannot certify 1 − δ_t."""
        return self.model.margin

    def leg_scale(self, refuted: bool) -> tuple[float | None, bool]:
        """The factor on the tube of a leg starting now, and whether it is its category's own.

        (None, False) while nothing certifies it (the caller keeps the bound unscaled). The
        finite stand-in of :func:`finite_margin` (at least 1) where δ_t fell below 1/(n + 1).
        """
        own = self.refuted if refuted else self.model
        scale = finite_margin(own, floor=1.0)
        if scale is not None or not refuted:
            return scale, scale is not None
        both = [*self.model.scores, *self.refuted.scores]
        pooled = conformal_quantile(both, self.model.config.delta)
        return (pooled if math.isfinite(pooled) else None), False

    @property
    def prior_margin(self) -> float:
        """m, the margin of a leg without a model; +inf while the scores cannot certify it."""
        return self.prior.margin

    def observe(self, deviation: float, tube: float, margin_used: float,
                adapt: bool, refuted: bool = False) -> None:
        """Account a finished leg.

        Its largest deviation (m), the tube predicted at its start (m; 0: none, a prior
        leg), the margin in force for it (m) and whether its tube rested on a refuted level.
        ``adapt``: the margin was this category's quantile (not a fallback).
        """
        if tube > 0.0:
            own = self.refuted if refuted else self.model
            own.observe(deviation / tube, margin_used / tube, adapt)
        else:
            self.prior.observe(deviation, margin_used, adapt)
