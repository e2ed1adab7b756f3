"""Disturbance signals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_sim.disturbance import DisturbanceGenerator, DisturbanceModel
from rrtq_sim.plant import rover_matrices
from rrtq_sim.riccati import solve_riccati

F4 = np.array([[0.0], [0.0], [-1.0], [1.0]])


def make(model, q=2, amplitude=1.5, frequency=0.25, seed=0, **kw):
    return DisturbanceGenerator(DisturbanceModel(model), q, amplitude, frequency, np.random.default_rng(seed), **kw)


def game(gamma=20.0):
    a, b = rover_matrices(40.0, 20.0, 45.0)
    return solve_riccati(a, b, 10.0 * np.eye(4), 2.0 * np.eye(2), 0.5 * np.eye(4), 10.0, F4, gamma)


def test_enum_values_are_the_yaml_names():
    assert [m.value for m in DisturbanceModel] == ['none', 'constant', 'sinusoid', 'gaussian', 'worst_case',
                                                  'field']
    assert DisturbanceModel('worst_case') is DisturbanceModel.WORST_CASE


def test_none_is_zero_of_the_right_size():
    d = make('none', q=3).value(12.0, np.ones(4), 1.0)
    np.testing.assert_array_equal(d, np.zeros(3))


def test_constant_is_amplitude_everywhere():
    gen = make('constant', amplitude=-0.7)
    for t in (0.0, 3.3, 100.0):
        np.testing.assert_array_equal(gen.value(t, np.zeros(4), 0.0), [-0.7, -0.7])


def test_sinusoid_has_the_requested_amplitude_and_frequency():
    gen = make('sinusoid', amplitude=2.0, frequency=0.25)
    assert gen.value(1.0, np.zeros(4), 0.0) == pytest.approx([2.0, 2.0])  # quarter period
    assert gen.value(2.0, np.zeros(4), 0.0) == pytest.approx([0.0, 0.0], abs=1e-12)
    assert gen.value(3.0, np.zeros(4), 0.0) == pytest.approx([-2.0, -2.0])
    assert gen.value(0.3, np.zeros(4), 0.0)[0] == pytest.approx(2.0 * math.sin(2 * math.pi * 0.25 * 0.3))


def test_gaussian_is_one_seeded_draw_per_call():
    gen = make('gaussian', q=2, amplitude=0.5, seed=42)
    got = np.array([gen.value(0.05 * k, np.zeros(4), 0.0) for k in range(5)])
    ref = np.random.default_rng(42)
    np.testing.assert_array_equal(got, np.array([ref.normal(0.0, 0.5, 2) for _ in range(5)]))
    again = make('gaussian', q=2, amplitude=0.5, seed=42)
    np.testing.assert_array_equal(again.value(0.0, np.zeros(4), 0.0), got[0])


def test_gaussian_statistics():
    gen = make('gaussian', q=1, amplitude=0.5, seed=1)
    draws = np.array([gen.value(0.0, np.zeros(4), 0.0)[0] for _ in range(20000)])
    assert abs(draws.mean()) < 0.02
    assert draws.std() == pytest.approx(0.5, rel=0.03)


def test_worst_case_is_the_game_disturbance_clipped():
    sol = game(20.0)
    gen = make('worst_case', q=1, amplitude=100.0, riccati=sol)
    xbar = np.array([1.0, -2.0, 0.5, 0.3])
    expected = F4.T @ sol.P(4.0) @ xbar / 20.0**2
    np.testing.assert_allclose(gen.value(0.0, xbar, 4.0), expected)
    np.testing.assert_allclose(gen.value(0.0, xbar, 4.0), sol.disturbance_gain(4.0) @ xbar)
    assert abs(expected[0]) > 0.01
    clipped = make('worst_case', q=1, amplitude=0.01, riccati=sol)
    np.testing.assert_allclose(clipped.value(0.0, xbar, 4.0), np.sign(expected) * 0.01)
    np.testing.assert_allclose(clipped.value(0.0, np.zeros(4), 4.0), [0.0])


def test_worst_case_uses_explicit_f_and_gamma_over_the_solution():
    sol = game(20.0)
    f = np.array([[1.0], [0.0], [0.0], [0.0]])
    gen = make('worst_case', q=1, amplitude=100.0, riccati=sol, F=f, gamma=10.0)
    xbar = np.array([1.0, -2.0, 0.5, 0.3])
    np.testing.assert_allclose(gen.value(0.0, xbar, 2.0), f.T @ sol.P(2.0) @ xbar / 100.0)


def test_worst_case_needs_a_riccati_solution_and_matching_shapes():
    with pytest.raises(ValueError, match='Riccati'):
        make('worst_case', q=1)
    with pytest.raises(ValueError, match='F must'):
        make('worst_case', q=2, riccati=game())
    with pytest.raises(ValueError, match='xbar'):
        make('worst_case', q=1, riccati=game()).value(0.0, np.zeros(3), 1.0)


def test_negative_std_is_rejected():
    with pytest.raises(ValueError):
        make('gaussian', amplitude=-1.0)
