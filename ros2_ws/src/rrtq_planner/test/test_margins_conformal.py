"""Conformal margin: coverage on exchangeable scores against the exact rank formula, the
adaptive form against its finite-sample guarantee on drifting scores, the policy's rules."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_planner.margins.conformal import (ConformalConfig, ConformalQuantile,
                                            aci_miss_rate_bound, conformal_quantile,
                                            minimum_scores)
from rrtq_planner.margins.coverage import binomial_interval
from rrtq_planner.margins.policy import ConformalPolicy, LegInfo, MarginSample


def test_quantile_is_the_rank_of_split_conformal():
    scores = np.array([5.0, 1.0, 4.0, 2.0, 3.0])
    # n = 5, δ = 0.2: ⌈6 · 0.8⌉ = 5th smallest; δ = 0.5: ⌈3⌉ = 3rd smallest.
    assert conformal_quantile(scores, 0.2) == 5.0
    assert conformal_quantile(scores, 0.5) == 3.0
    assert conformal_quantile(scores, 0.1) == math.inf        # ⌈5.4⌉ = 6 > n
    assert conformal_quantile(scores, 1.5) == 0.0
    # ⌈1/δ⌉ − 1 scores are the fewest with a finite quantile.
    for delta in (0.05, 0.1, 0.2, 1 / 3):
        k = minimum_scores(delta)
        assert math.isfinite(conformal_quantile(np.ones(k), delta))
        assert conformal_quantile(np.ones(k - 1), delta) == math.inf
    assert minimum_scores(0.05) == 19


@pytest.mark.parametrize('n', [19, 30, 49])
def test_coverage_on_exchangeable_scores_is_the_exact_rank_fraction(n):
    # For exchangeable continuous scores P(next <= q) = rank / (n + 1) exactly, at least
    # 1 − δ. 20000 repetitions, vectorised: a Clopper-Pearson interval of the observed
    # coverage must contain that value; for n = 30 (rank 30/31 = 0.968) its lower end must
    # also clear 1 − δ.
    delta, reps = 0.05, 20000
    rng = np.random.default_rng(n)
    s = rng.lognormal(0.0, 0.7, (reps, n + 1))
    rank = math.ceil((n + 1) * (1 - delta) - 1e-9)
    q = np.sort(s[:, :n], axis=1)[:, rank - 1]
    np.testing.assert_array_equal(q, [conformal_quantile(row, delta) for row in s[:50, :n]]
                                  + list(q[50:]))
    covered = int((s[:, n] <= q).sum())
    low, high = binomial_interval(covered, reps, 0.99)
    exact = rank / (n + 1)
    assert exact >= 1 - delta
    assert low <= exact <= high
    if n == 30:
        assert low >= 1 - delta


def _stream_miss_rate(scores, calibration, eta):
    q = ConformalQuantile(ConformalConfig(window=50, adaptation=eta), calibration)
    for x in scores:
        q.observe(x, q.margin)
    return q.misses, q.legs


def test_adaptive_form_keeps_coverage_on_drifting_scores_where_the_plain_form_does_not():
    # Scores that double every 70 legs (a condition that keeps worsening): the plain window
    # lags behind and misses more often than δ; the adaptive level keeps the long-run miss
    # rate within its guarantee |rate − δ| <= (max(δ, 1−δ) + η) / (η T) (Gibbs & Candès 2021).
    rng = np.random.default_rng(3)
    legs, delta, eta = 3000, 0.05, 0.05
    scores = np.exp(0.01 * np.arange(legs)) * np.abs(rng.standard_normal(legs))
    calibration = np.abs(rng.standard_normal(50))
    misses, n = _stream_miss_rate(scores, calibration, 0.0)
    assert binomial_interval(misses, n, 0.99)[0] > delta
    misses, n = _stream_miss_rate(scores, calibration, eta)
    assert abs(misses / n - delta) <= aci_miss_rate_bound(delta, eta, n)
    # On exchangeable scores the plain window misses at its exact rate 1 − 49/51 (< δ), the
    # adaptive one at δ within its guarantee.
    iid = np.abs(rng.standard_normal(legs))
    misses, n = _stream_miss_rate(iid, iid[:50], 0.0)
    low, high = binomial_interval(misses, n, 0.99)
    assert low <= 2 / 51 <= high
    misses, n = _stream_miss_rate(iid, iid[:50], eta)
    assert abs(misses / n - delta) <= aci_miss_rate_bound(delta, eta, n)


def _leg_sample(t, index, y, start=(0.0, 0.0), target=(10.0, 0.0)):
    leg = LegInfo(index, np.array(start), np.array(target), 10.0)
    return MarginSample(t, np.array([5.0, y, 0.0, 0.0]), leg)


def _run_legs(policy, deviations):
    """One sample per deviation; each entry of ``deviations`` is one leg's profile."""
    out = []
    t = 0.0
    for index, profile in enumerate(deviations):
        for y in profile:
            out.append(policy.step(_leg_sample(t, index, y)))
            t += 0.05
    return out


def test_policy_starts_at_the_running_max_then_drops_the_transient():
    # δ = 0.1: 9 scores make the quantile finite, but with n < 19 its rank ⌈(n+1) 0.9⌉ is n,
    # the largest score; from n = 19 on it is the second largest, and the transient of the
    # first leg (2.0) no longer sets the margin.
    policy = ConformalPolicy(ConformalConfig(confidence=0.9, adaptation=0.0))
    legs = [[0.0, 2.0]] + [[0.0, 0.3 + 0.01 * i] for i in range(1, 21)]
    status = _run_legs(policy, legs)
    first = [status[2 * k] for k in range(len(legs))]
    assert first[0].leg_margin == 0.0                        # running max before anything
    assert [s.leg_margin for s in first[1:19]] == pytest.approx([2.0] * 18)
    assert first[8].bound == math.inf and first[9].bound == pytest.approx(2.0)
    assert first[19].leg_margin == pytest.approx(0.48)
    assert first[20].leg_margin == pytest.approx(0.49)
    assert status[-1].margin == pytest.approx(0.50)          # raised at once by the last leg
    assert status[-1].violations == 3     # leg 0 (above 0) and legs 19, 20 (each a new high)
    assert status[-1].samples == 20


def test_calibration_gives_a_finite_margin_from_the_first_leg_and_raises_at_once():
    calibration = [0.2] * 18 + [0.25]
    policy = ConformalPolicy(ConformalConfig(), calibration=calibration)
    status = _run_legs(policy, [[0.0, 0.1, 0.15], [0.0, 0.4, 0.6, 0.1], [0.0, 0.1]])
    assert status[0].leg_margin == pytest.approx(0.25)      # rank 19 of 19: the largest
    assert status[0].margin == pytest.approx(0.25)
    # Leg 1 goes to 0.6: the margin follows at once, the violation is flagged once.
    leg1 = status[3:7]
    assert [s.margin for s in leg1] == pytest.approx([0.25, 0.4, 0.6, 0.6])
    assert [s.violation for s in leg1] == [False, True, False, False]
    assert leg1[-1].violations == 1
    # Leg 2: the score 0.6 joined the window (20 scores: rank 20 = 0.6); still one violation.
    assert status[7].leg_margin == pytest.approx(0.6)
    assert status[-1].violations == 1
    assert policy.scores == pytest.approx([0.15, 0.6])


def test_warm_up_legs_do_not_lower_the_adaptive_level():
    # Without calibration the first ⌈1/δ⌉ − 1 = 19 legs run on the conservative start, not on
    # a prediction of the quantile: they must not move δ_t (each would add ηδ, and after 19
    # of them the quantile would turn finite at 13 scores, at the level 1 − δ_t ≈ 0.92).
    policy = ConformalPolicy(ConformalConfig(adaptation=0.05))
    status = _run_legs(policy, [[0.0, 0.3 - 0.001 * i] for i in range(21)])
    first = [status[2 * k] for k in range(21)]
    assert policy.quantile.delta_t == pytest.approx(0.05 + 0.05 * 0.05)   # leg 19 only
    assert all(math.isinf(s.bound) for s in first[:19])
    assert first[19].bound == pytest.approx(0.3) and first[19].confidence == pytest.approx(0.95)
    assert first[19].leg_margin == pytest.approx(0.3)


def _published_coverage(statuses):
    """Per leg (by ``legs``): its largest ``d_rob`` against the least ``margin`` published."""
    legs: dict[int, list[float]] = {}
    for s in statuses:
        row = legs.setdefault(s.legs, [0.0, math.inf])
        row[0], row[1] = max(row[0], s.d_rob), min(row[1], s.margin)
    return sum(d > m for d, m in legs.values()), len(legs)


@pytest.mark.parametrize('eta', [0.0, 0.05])
def test_published_margin_covers_exchangeable_legs_at_the_stated_rate(eta):
    # What an outside check reads off /safety/status: per leg, the realised deviation against
    # the least margin published while the leg ran (a margin raised during the leg does not
    # cover it). With 19 calibration scores and 400 exchangeable legs, the miss rate must be
    # compatible with δ (lower end of its 95 % interval <= δ) and not far below it either.
    rng = np.random.default_rng(11)
    draws = np.abs(rng.standard_normal(419))
    policy = ConformalPolicy(ConformalConfig(adaptation=eta), calibration=draws[:19])
    status = _run_legs(policy, [[0.0, 0.5 * x, x, 0.5 * x] for x in draws[19:]])
    misses, legs = _published_coverage(status)
    assert legs == 400 and misses == status[-1].violations
    low, high = binomial_interval(misses, legs)
    assert low <= 0.05 <= high + 0.02


def test_drifting_legs_keep_the_published_coverage_only_with_the_adaptive_level():
    # Leg deviations that double every 70 legs: judged from the published statuses, the
    # plain window misses significantly more often than δ; the adaptive one, which learns
    # from the misses of the published margin (the conservative start included, when δ_t
    # has made the quantile infinite), stays within its guarantee.
    rng = np.random.default_rng(5)
    x = np.exp(0.01 * np.arange(1500)) * np.abs(rng.standard_normal(1500))
    calibration = np.abs(rng.standard_normal(50))
    rates = {}
    for eta in (0.0, 0.05):
        policy = ConformalPolicy(ConformalConfig(adaptation=eta), calibration=calibration)
        misses, legs = _published_coverage(_run_legs(policy, [[0.0, v] for v in x]))
        rates[eta] = (misses, legs)
    assert binomial_interval(*rates[0.0], 0.99)[0] > 0.05
    misses, legs = rates[0.05]
    assert abs(misses / legs - 0.05) <= aci_miss_rate_bound(0.05, 0.05, legs)
