"""The margin policies: running_max is the safety core's margin exactly; learned_bound on a
true plant with a field bump covers the legs and the field; calibration files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.signal import lfilter

from rrtq_controller.legs import LegSequencer
from rrtq_planner.margins.coverage import binomial_interval
from rrtq_planner.margins.calibration import (Calibration, read_calibration,
                                              write_calibration)
from rrtq_planner.margins.learned import LearnedBoundConfig, LearnedBoundPolicy
from rrtq_planner.margins.policy import LegInfo, MarginMode, MarginSample, RunningMaxPolicy
from rrtq_planner.safety import Leg, SafetyConfig, SafetyMonitor
from rrtq_sim.field import Bump, DisturbanceField, compose_input_matrix
from rrtq_sim.plant import Plant, rover_matrices


def test_running_max_is_the_safety_monitors_margin_step_for_step():
    rng = np.random.default_rng(0)
    monitor = SafetyMonitor(SafetyConfig(robot_radius=0.0))
    policy = RunningMaxPolicy()
    leg = None
    for k in range(3000):
        if k % 97 == 0 or leg is None:
            start = rng.uniform(-10, 10, 2)
            d0 = 0.0 if rng.random() < 0.1 else float(rng.uniform(1, 6))
            leg = LegInfo(k // 97, start, start + rng.normal(0, 3, 2), d0)
        state = np.concatenate([rng.uniform(-12, 12, 2), rng.normal(0, 1, 2)])
        sample = MarginSample(0.05 * k, state, leg if rng.random() > 0.05 else None)
        # The safety node's own step (its guard on the leg included), as the node calls it.
        seen = None if sample.leg is None else Leg(sample.leg.index, tuple(sample.leg.start),
                                                   tuple(sample.leg.target), sample.leg.d0)
        node = monitor.step(50_000_000 * k, state[:2], None, seen)
        status = policy.step(sample)
        assert status.margin == node.margin and status.d_rob == node.d_rob
        assert status.d_rob_max == node.d_rob_max and status.mode is MarginMode.RUNNING_MAX


PD = np.array([[40.0, 0.0, 30.0, 0.0], [0.0, 40.0, 0.0, 30.0]])


def _mission(policy, steps=3000, seed=0):
    """The rover without a spring between random waypoints of a 12 m square under a PD law
    with probing that decays leg by leg (strong on the first: the transient), through a field
    bump. (Waypoints in varied directions: along a straight route the legs' frame moves with
    the robot and a model-free fit cannot tell a field from a spring; see docs/margins.md.)"""
    a_mat, b_mat = rover_matrices(40.0, 0.0, 45.0)
    dt = 0.05
    plant = Plant(a_mat, b_mat, compose_input_matrix(None, 4), dt, 1000.0)
    field = DisturbanceField([Bump((6.0, 6.0), 4.0, (0.15, -0.2))])
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((steps, 2))
    probe = lfilter([np.sqrt(1 - 0.95**2)], [1.0, -0.95], white, axis=0)
    route = rng.uniform(0.0, 12.0, (60, 2))
    legs = LegSequencer(rho=0.15, horizon=10.0)
    x = np.zeros(4)
    legs.set_plan(route, x, 0.0)
    rows = []
    prev = None
    for k in range(steps):
        t = k * dt
        sample = MarginSample(t, x) if prev is None else MarginSample(
            t, x, prev['leg'], prev['u'], prev['probe'], lambda tau: PD, 10.0)
        status = policy.step(sample)
        rows.append((status, None if prev is None else prev['leg'].index))
        legs.update(x, t)
        leg = legs.leg
        std = 60.0 * 0.6 ** leg.index
        p = std * probe[k]
        u = -PD @ (x - leg.target) + p
        prev = {'leg': LegInfo(leg.index, leg.x0[:2].copy(), leg.target[:2].copy(), leg.d0),
                'u': u, 'probe': p}
        x = plant.step(x, u, field.acceleration(x), np.zeros(2))
    return rows, plant, field


def test_learned_bound_covers_the_legs_and_the_field_on_a_true_plant():
    config = LearnedBoundConfig(region=((-2.0, 14.0), (-2.0, 14.0)), dt=0.05)
    policy = LearnedBoundPolicy(config)
    rows, plant, field = _mission(policy)
    status = rows[-1][0]
    legs = policy.scores
    assert len(legs) >= 12
    # Coverage: each finished leg's largest deviation within the margin in force at its
    # start, on at least 1 − δ of the legs up to binomial slack.
    starts = {}
    for s, index in rows:
        starts.setdefault(index, s.leg_margin)
    margins = [starts[i] for i in range(len(legs))]
    misses = sum(score > m for score, m in zip(legs, margins))
    assert misses == status.violations - (rows[-1][0].leg_margin < policy.legs.leg_max)
    assert binomial_interval(misses, len(legs))[0] <= 1 - config.confidence
    # The early transient set the running max; the learned margin fell under it.
    assert status.d_rob_max > 1.0
    assert status.leg_margin < status.d_rob_max
    # The bank's bound covers the true field on the cells it was taken over, component by
    # component (level × R_i), and the fit's band covers the true residual there.
    cells = policy.cells[policy.region]
    assert len(cells) > 0
    truth = field.acceleration(cells) @ plant.gamma_d.T
    level = policy.bank.level
    assert np.all(np.abs(truth) <= level * policy._prior_residual + 1e-12)
    mean, half = policy.fit.band(policy._cell_phi[policy.region])
    assert np.all(np.abs(mean - truth) <= half)
    # The model the tube runs on is the plant's.
    assert np.abs(policy.theta[:, :4] - plant.phi).max() < 2e-3
    assert status.bound == pytest.approx(level * config.prior_bound)


def test_calibration_round_trip_and_bad_files(tmp_path):
    good = tmp_path / 'run.calibration.json'
    cal = Calibration((0.4, 0.2), 'rrtqx-paper seed 7', '2026-12-01T17:27:00Z')
    write_calibration(good, cal.extended([0.3]))
    back = read_calibration(good)
    assert back.scores == (0.4, 0.2, 0.3) and back.source == 'rrtqx-paper seed 7'
    cases = {
        'notjson': 'scores: [1, 2]',
        'list': '[0.1, 0.2]',
        'format': json.dumps({'format': 'other', 'version': 1, 'scores': []}),
        'version': json.dumps({'format': 'rrtq-margin-calibration', 'version': 2, 'scores': []}),
        'key': json.dumps({'format': 'rrtq-margin-calibration', 'version': 1, 'scores': [],
                           'window': 5}),
        'negative': json.dumps({'format': 'rrtq-margin-calibration', 'version': 1,
                                'scores': [0.1, -1.0]}),
        'nan': '{"format": "rrtq-margin-calibration", "version": 1, "scores": [NaN]}',
        'notlist': json.dumps({'format': 'rrtq-margin-calibration', 'version': 1,
                               'scores': 0.5}),
    }
    expect = {'notjson': 'not a JSON', 'list': 'JSON object', 'format': 'format',
              'version': 'version 2', 'key': "'window'", 'negative': '-1.0', 'nan': 'nan',
              'notlist': 'list'}
    for name, text in cases.items():
        bad = tmp_path / f'{name}.json'
        bad.write_text(text)
        with pytest.raises(ValueError) as err:
            read_calibration(bad)
        assert str(bad) in str(err.value) and expect[name] in str(err.value)
    with pytest.raises(ValueError, match='missing.json'):
        read_calibration(tmp_path / 'missing.json')
    assert math.isfinite(sum(back.scores))
