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


def test_the_scale_grows_the_current_legs_margin_and_leaves_far_obstacles_predictions():
    """The same mission seen by a calibrated and an uncalibrated policy (the rover's flight
    does not depend on them): the calibrated leg margin is the uncalibrated one times the
    scale (2 here), and an obstacle no leg has come near keeps the uncalibrated prediction --
    scaled, bump_mid's scale of 2.2 shut its far gap (docs/margins.md §10.1)."""
    config = LearnedBoundConfig(region=((-2.0, 14.0), (-2.0, 14.0)), dt=0.05, prior_bound=0.5)
    plain = LearnedBoundPolicy(config)
    calibrated = LearnedBoundPolicy(config, calibrated=CalibratedScale(
        ConformalConfig(window=50), (2.0,) * 40, (0.5,) * 40))
    rows = {}
    for name, policy in (('plain', plain), ('calibrated', calibrated)):
        rows[name] = [s for s, _ in _mission(policy, steps=900, seed=4)[0]]
    last = {name: r[-1] for name, r in rows.items()}
    assert last['calibrated'].scale == 2.0 and last['plain'].leg_tube > 0.0
    assert last['calibrated'].leg_tube == pytest.approx(last['plain'].leg_tube, rel=1e-12)
    assert last['calibrated'].leg_margin == pytest.approx(2.0 * last['plain'].leg_margin,
                                                          rel=1e-12)
    wall = np.array([[20.0, 30.0], [24.0, 30.0], [24.0, 31.0], [20.0, 31.0]])
    far = {name: p.obstacle_margin('wall', wall) for name, p in (('plain', plain),
                                                                   ('calibrated', calibrated))}
    assert far['plain'] > 0.0 and far['calibrated'] == far['plain']
