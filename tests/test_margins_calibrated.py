"""The conformalized learned bound (docs/margins.md §10): its guarantee and what it assumes.

The scores are drawn from a known generator, so the coverage a calibration gives new missions
is checked against the generator itself, not against the code's own accounting.
"""

import math

import numpy as np
import pytest

from rrtq_planner.margins.calibration import Calibration
from rrtq_planner.margins.conformal import CalibratedScale, ConformalConfig, aci_miss_rate_bound
from rrtq_planner.margins.coverage import binomial_interval
from rrtq_planner.margins.learned import LearnedBoundConfig, LearnedBoundPolicy

from rrtq_testing.margin_missions import rover_mission as _mission

DELTA = 0.05
PRIOR_LEGS = 3


def missions(rng, count, legs=15, gust=1.0):
    """Legs of ``count`` missions: (deviation m, tube m; 0 for the first legs, which have none).

    A leg's tube varies over two orders of magnitude (where it runs, how soft the loop is);
    its deviation is the tube times a heavy-tailed factor, ``gust`` times larger on the first
    legs, which run before the model contracts and are scored raw.
    """
    out = []
    for _ in range(count):
        mission = []
        for k in range(legs):
            if k < PRIOR_LEGS:
                mission.append((gust * 0.3 * float(rng.gamma(2.0, 0.5)), 0.0))
            else:
                tube = float(np.exp(rng.uniform(np.log(0.05), np.log(5.0))))
                mission.append((tube * float(rng.gamma(4.0, 0.12)), tube))
        out.append(mission)
    return out


def calibration_of(legs):
    return Calibration(tuple(d for d, _ in legs),
                       normalized=tuple(d / p for d, p in legs if p > 0.0),
                       prior=tuple(d for d, p in legs if p <= 0.0))


def fly(scale, mission):
    """One mission's legs under a calibration: (deviation, margin in force) per leg."""
    out = []
    for deviation, tube in mission:
        margin = tube * scale.scale if tube > 0.0 else scale.prior_margin
        out.append((deviation, margin))
        scale.observe(deviation, tube, margin, adapt=True)
    return out


def test_a_calibration_pooled_from_other_missions_covers_every_leg_of_new_ones():
    """Exchangeable missions (drawn from the same generator): each new mission starts from a
    calibration pooled from 20 others, and its legs -- the first ones included -- stay under
    their margin on 1 − δ of them, in each category, with the normalized scores' margin
    following the tube where a raw quantile of all legs could not."""
    rng = np.random.default_rng(7)
    config = ConformalConfig(confidence=1 - DELTA, window=50, adaptation=0.0)
    flown = []
    for trial in range(150):
        pool = [leg for m in missions(rng, 20) for leg in m]
        cal = calibration_of(pool)
        scale = CalibratedScale(config, cal.normalized, cal.prior)
        assert math.isfinite(scale.scale) and math.isfinite(scale.prior_margin)
        mission = missions(rng, 1)[0]
        flown += [(d, m, p) for (d, m), (_, p) in zip(fly(scale, mission), mission)]
    first = [(d, m) for d, m, p in flown if p <= 0.0]
    later = [(d, m) for d, m, p in flown if p > 0.0]
    for legs in (first, later, first + later):
        misses = sum(d > m for d, m in legs)
        low, high = binomial_interval(misses, len(legs))
        assert low <= DELTA <= high, (misses, len(legs))
    # Locally adaptive: the margin follows the tube; one raw quantile of every leg would be
    # far wider on the small tubes and too narrow on the large ones.
    margins = np.array([m for _, m in later])
    assert margins.max() / margins.min() > 20.0


def test_scores_from_another_generator_break_the_guarantee_and_the_adaptive_level_repairs_it():
    """The guarantee assumes the calibration's missions are exchangeable with the new ones
    (same robot, layouts and disturbances drawn from the same generator). Calibrated on
    missions whose deviations were 0.4 times these (a calmer world), every mission started
    from that file misses far more than δ in both categories; one robot that carries its
    calibration from mission to mission, its adaptive level (Gibbs & Candès) with it, keeps
    each category's long-run miss rate within its bound of δ."""
    rng = np.random.default_rng(3)
    calm = [(0.4 * d, p) for m in missions(rng, 20) for d, p in m]
    cal = calibration_of(calm)
    new = missions(rng, 60)
    for eta in (0.0, 0.05):
        config = ConformalConfig(confidence=1 - DELTA, window=50, adaptation=eta)
        carried = CalibratedScale(config, cal.normalized, cal.prior)
        flown = [(d, m, p) for mission in new
                 for (d, m), (_, p) in zip(
                     fly(carried if eta else CalibratedScale(config, cal.normalized, cal.prior),
                         mission), mission)]
        for prior in (True, False):
            legs = [(d, m) for d, m, p in flown if (p <= 0.0) == prior]
            rate = sum(d > m for d, m in legs) / len(legs)
            if eta == 0.0:
                assert rate > 3 * DELTA, (prior, rate)
            else:
                assert abs(rate - DELTA) <= aci_miss_rate_bound(DELTA, eta, len(legs)), \
                    (prior, rate)


def bump_missions(rng, count, legs=15):
    """Legs of missions through fields the model meets as it goes: (deviation, tube, refuted).

    A leg with a model rests on the prior bound (2 in 3) or on a level residuals raised
    (refuted, a field already met). On the prior bound one leg in six enters a field the data
    had not shown and deviates six times as much; a refuted level bounds a field that was
    measured, and its tube is conservative.
    """
    out = []
    for mission in missions(rng, count, legs):
        flown = []
        for deviation, tube in mission:
            refuted = tube > 0.0 and rng.uniform() < 1 / 3
            if tube > 0.0:
                deviation *= 0.5 if refuted else (6.0 if rng.uniform() < 1 / 6 else 1.0)
            flown.append((deviation, tube, refuted))
        out.append(flown)
    return out


def test_legs_on_a_refuted_level_are_their_own_category_and_keep_their_tighter_margin():
    """Three Mondrian categories (docs/margins.md §10): every category of new missions stays
    under its margin on 1 − δ of its legs, and a leg on a refuted level is not charged for the
    fields entered unseen on the prior bound: its scale is well under the one quantile of both
    (bump_mid: 3.1 on every model leg shut the gap from inside the learned bump). Until its
    category can certify, a refuted leg takes that pooled quantile and does not move its
    category's level."""
    rng = np.random.default_rng(11)
    config = ConformalConfig(confidence=1 - DELTA, window=50, adaptation=0.0)
    flown, ratios = [], []
    for trial in range(150):
        pool = [leg for m in bump_missions(rng, 20) for leg in m]
        scale = CalibratedScale(config, [d / p for d, p, up in pool if p > 0.0 and not up],
                                [d for d, p, _ in pool if p <= 0.0],
                                [d / p for d, p, up in pool if up])
        both = CalibratedScale(config, [d / p for d, p, _ in pool if p > 0.0])
        own, certified = scale.leg_scale(True)
        assert certified and own is not None and math.isfinite(both.scale)
        ratios.append(own / both.scale)
        for deviation, tube, refuted in bump_missions(rng, 1)[0]:
            if tube > 0.0:
                factor, certified = scale.leg_scale(refuted)
                assert certified and factor is not None
                margin = tube * factor
            else:
                margin = scale.prior_margin
            flown.append((deviation, margin, 'prior' if tube <= 0.0 else refuted))
            scale.observe(deviation, tube, margin, True, refuted)
    for category in ('prior', False, True):
        legs = [(d, m) for d, m, c in flown if c == category]
        misses = sum(d > m for d, m in legs)
        low, high = binomial_interval(misses, len(legs))
        assert low <= DELTA <= high, (category, misses, len(legs))
    assert np.median(ratios) < 0.5, np.median(ratios)
    # No refuted scores yet: the quantile of both model categories, and no adaptation.
    fresh = CalibratedScale(ConformalConfig(window=50, adaptation=0.05),
                            [0.2] * 10 + [0.9] * 30, refuted=[0.1] * 5)
    assert fresh.leg_scale(True) == (pytest.approx(0.9), False)
    assert fresh.leg_scale(False) == (pytest.approx(0.9), True)
    fresh.observe(5.0, 1.0, 0.9, False, True)
    assert fresh.refuted.delta_t == fresh.refuted.config.delta and list(fresh.refuted.scores)[-1] == 5.0
    assert list(fresh.model.scores)[-1] == 0.9


def test_a_leg_on_a_refuted_level_takes_its_categorys_scale_in_the_policy():
    """learned_bound on the rover through a bump the prior bound (0.1 m/s²) understates: once
    residuals raise the bank above it, the legs are marked refuted (the bound the status
    publishes above the prior bound at their start) and grown by their tube times the refuted
    category's scale (1.2 here); a leg on the prior bound by the normalized one's (2)."""
    config = LearnedBoundConfig(region=((-2.0, 14.0), (-2.0, 14.0)), dt=0.05, prior_bound=0.1)
    policy = LearnedBoundPolicy(config, calibrated=CalibratedScale(
        ConformalConfig(window=50), (2.0,) * 40, (0.5,) * 40, (1.2,) * 40))
    starts: dict[int, object] = {}
    for status, _ in _mission(policy, steps=1500, seed=4)[0]:
        starts.setdefault(status.legs, status)
    with_tube = [s for s in starts.values() if s.leg_tube > 0.0]
    kinds = {s.leg_refuted for s in with_tube}
    assert kinds == {False, True}, kinds
    for s in with_tube:
        assert s.leg_refuted == (s.bound > config.prior_bound * (1 + 1e-9))
        assert s.scale == (1.2 if s.leg_refuted else 2.0)
        assert s.leg_margin == pytest.approx(s.scale * s.leg_tube, rel=1e-12)
    assert not any(s.leg_refuted for s in starts.values() if s.leg_tube <= 0.0)


def _legs(rows):
    """Per leg (as /safety/status counts them): (largest deviation, tube, margin at start,
    least published margin), as the recording's reader takes them."""
    legs = {}
    for status, _ in rows:
        if status.legs == 0:
            continue
        row = legs.setdefault(status.legs, [0.0, status.leg_tube, status.leg_margin, math.inf])
        row[0] = status.leg_deviation
        row[3] = min(row[3], status.margin)
    return [legs[k] for k in sorted(legs)]


def test_the_first_legs_margin_comes_from_the_calibration_not_the_running_max():
    """learned_bound on the rover (the missions of test_margins_policy): calibrated from
    eight other missions, its first leg is grown by the calibrated prior margin (without a
    calibration: about 0, the running max of nothing), a leg with a model by its tube times the
    scale, and the published margin never drops below the leg's within it."""
    config = LearnedBoundConfig(region=((-2.0, 14.0), (-2.0, 14.0)), dt=0.05, prior_bound=0.5)
    # δ = 0.2: a quantile from four scores (a mission here has one first leg).
    conformal = ConformalConfig(confidence=0.8, window=config.window)
    pool = []
    for other in range(11, 19):
        rows, _, _ = _mission(LearnedBoundPolicy(config, calibrated=CalibratedScale(conformal)),
                              steps=800, seed=other)
        pool += [(d, tube) for d, tube, _, _ in _legs(rows)]
    cal = calibration_of(pool)
    assert len(cal.prior) >= 4 and len(cal.normalized) >= 4, (len(cal.prior), len(cal.normalized))
    policy = LearnedBoundPolicy(config, calibrated=CalibratedScale(conformal, cal.normalized,
                                                                   cal.prior))
    rows, _, _ = _mission(policy, steps=1500, seed=0)
    legs = _legs(rows)
    plain, _, _ = _mission(LearnedBoundPolicy(config), steps=200, seed=0)
    assert _legs(plain)[0][2] < 1e-3                     # uncalibrated: ~nothing on leg one
    first = legs[0]
    assert first[1] == 0.0 and first[2] > 100 * _legs(plain)[0][2]   # no tube; calibrated
    model_legs = [leg for leg in legs if leg[1] > 0.0]
    assert model_legs
    for deviation, tube, at_start, least in legs:
        assert least >= at_start - 1e-12                 # the leg's margin does not drop
    scale = CalibratedScale(conformal, cal.normalized, cal.prior)
    assert first[2] == pytest.approx(scale.prior_margin)
    assert model_legs[0][2] == pytest.approx(model_legs[0][1] * scale.scale, rel=1e-9)


def test_a_first_leg_grows_the_obstacles_it_can_reach_by_the_calibrated_margin():
    """Before a contracting model, the calibrated first-leg margin grows what the current leg
    can reach (within that margin and the robot radius of its segment); a far obstacle keeps
    the uncalibrated fallback, or a far gap would shut before the robot has moved."""
    from rrtq_planner.margins.policy import LegInfo, MarginSample
    from rrtq_testing.margin_missions import PD
    config = LearnedBoundConfig(region=((-2.0, 14.0), (-2.0, 14.0)), dt=0.05)
    calibrated = CalibratedScale(ConformalConfig(window=50), (0.5,) * 30, (0.8,) * 30)
    policy = LearnedBoundPolicy(config, calibrated=calibrated)
    leg = LegInfo(0, np.zeros(2), np.array([6.0, 0.0]), 6.0)
    status = policy.step(MarginSample(0.0, np.zeros(4), leg, np.zeros(2), np.zeros(2),
                                      lambda tau: PD, 10.0))
    assert status.margin == pytest.approx(0.8) and status.local is not None
    square = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    assert status.local('near', square + [3.0, 1.7]) == pytest.approx(0.8)   # 1.2 m off
    assert status.local('far', square + [3.0, 8.0]) == 0.0       # the running max, 0 yet
    assert LearnedBoundPolicy(config).step(MarginSample(0.0, np.zeros(4), leg)).local is None


def test_the_scale_grows_the_current_legs_margin_and_shrinks_far_obstacles_predictions_only():
    """The same mission seen by calibrated and uncalibrated policies (the rover's flight
    does not depend on them): the calibrated leg margin is the uncalibrated one times the
    scale (2 here), and an obstacle no leg has come near keeps the uncalibrated prediction --
    scaled up, bump_mid's scale of 2.2 shut its far gap (docs/margins.md §10.1) -- unless
    the scale is below 1 (0.4 here): then the prediction shrinks with it."""
    config = LearnedBoundConfig(region=((-2.0, 14.0), (-2.0, 14.0)), dt=0.05, prior_bound=0.5)
    plain = LearnedBoundPolicy(config)
    calibrated = LearnedBoundPolicy(config, calibrated=CalibratedScale(
        ConformalConfig(window=50), (2.0,) * 40, (0.5,) * 40))
    tight = LearnedBoundPolicy(config, calibrated=CalibratedScale(
        ConformalConfig(window=50), (0.4,) * 40, (0.5,) * 40))
    rows = {}
    for name, policy in (('plain', plain), ('calibrated', calibrated), ('tight', tight)):
        rows[name] = [s for s, _ in _mission(policy, steps=900, seed=4)[0]]
    last = {name: r[-1] for name, r in rows.items()}
    assert last['calibrated'].scale == 2.0 and last['plain'].leg_tube > 0.0
    assert last['calibrated'].leg_tube == pytest.approx(last['plain'].leg_tube, rel=1e-12)
    assert last['calibrated'].leg_margin == pytest.approx(2.0 * last['plain'].leg_margin,
                                                          rel=1e-12)
    wall = np.array([[20.0, 30.0], [24.0, 30.0], [24.0, 31.0], [20.0, 31.0]])
    far = {name: p.obstacle_margin('wall', wall) for name, p in (
        ('plain', plain), ('calibrated', calibrated), ('tight', tight))}
    assert last['tight'].scale == 0.4 and not last['tight'].leg_refuted
    assert far['plain'] > 0.0 and far['calibrated'] == far['plain']
    assert far['tight'] == pytest.approx(0.4 * far['plain'], rel=1e-12)
