"""Plant: exact ZOH discretisation against a numerical ODE solution of the continuous system."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from rrtq_sim.plant import Plant, rover_matrices

DT = 0.05
F4 = np.array([[0.0], [0.0], [-1.0], [1.0]])


def reference_step(a, b, f, x, u, d, anchor, dt):
    """Integrate x' = A (x - offset) + B u + F d with u, d constant over dt."""
    offset = np.zeros(len(x))
    offset[:2] = anchor
    drive = b @ u + (f @ d if f.shape[1] else 0.0)
    sol = solve_ivp(lambda _t, y: a @ (y - offset) + drive, (0.0, dt), x, rtol=1e-10, atol=1e-12)
    return sol.y[:, -1]


def test_rover_matrices_match_paper_eq26():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    assert a[2, 0] == a[3, 1] == pytest.approx(-0.5)
    assert a[2, 2] == a[3, 3] == pytest.approx(-1.125)
    assert b[2, 0] == b[3, 1] == pytest.approx(0.025)
    assert a[0, 2] == a[1, 3] == 1.0
    assert np.count_nonzero(a) == 6 and np.count_nonzero(b) == 2


@pytest.mark.parametrize('stiffness', [20.0, 0.0])
def test_rover_step_matches_ode(stiffness):
    a, b = rover_matrices(40.0, stiffness, 45.0)
    plant = Plant(a, b, F4, DT, 1000.0)
    x = np.array([3.0, -2.0, 0.4, -0.7])
    u, d, anchor = np.array([30.0, -12.0]), np.array([0.8]), np.array([1.5, 2.5])
    got = plant.step(x, u, d, anchor)
    np.testing.assert_allclose(got, reference_step(a, b, F4, x, u, d, anchor, DT), rtol=1e-9, atol=1e-11)
    assert (plant.n, plant.m, plant.q, plant.dt) == (4, 2, 1, DT)


def test_lti_step_matches_ode_over_long_step():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(3, 3))  # generic, possibly unstable
    b = rng.normal(size=(3, 1))
    f = rng.normal(size=(3, 2))
    plant = Plant(a, b, f, 0.7, 50.0)
    x, u, d, anchor = rng.normal(size=3), np.array([4.0]), np.array([0.3, -1.1]), np.array([-0.5, 0.9])
    np.testing.assert_allclose(plant.step(x, u, d, anchor), reference_step(a, b, f, x, u, d, anchor, 0.7), rtol=1e-9)


def test_repeated_steps_compose_to_one_long_interval():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    plant = Plant(a, b, F4, DT, 1000.0)
    x0, u, d, anchor = np.array([1.0, 2.0, 0.0, 0.0]), np.array([5.0, 7.0]), np.array([0.2]), np.zeros(2)
    x = x0
    for _ in range(40):
        x = plant.step(x, u, d, anchor)
    np.testing.assert_allclose(x, reference_step(a, b, F4, x0, u, d, anchor, 40 * DT), rtol=1e-8)


def test_saturation_clips_each_axis_independently():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    plant = Plant(a, b, F4, DT, 100.0)
    np.testing.assert_array_equal(plant.saturate([250.0, -40.0]), [100.0, -40.0])
    np.testing.assert_array_equal(plant.saturate([-1e9, 1e9]), [-100.0, 100.0])
    x = np.array([0.0, 0.0, 1.0, 0.0])
    np.testing.assert_allclose(
        plant.step(x, [250.0, -40.0], [0.0], [0.0, 0.0]), plant.step(x, [100.0, -40.0], [0.0], [0.0, 0.0])
    )
    assert not np.allclose(plant.step(x, [250.0, 0.0], [0.0], [0, 0]), plant.step(x, [99.0, 0.0], [0.0], [0, 0]))


def test_non_finite_force_is_rejected():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    plant = Plant(a, b, F4, DT, 100.0)
    with pytest.raises(ValueError, match='finite'):
        plant.step(np.zeros(4), [np.nan, 0.0], [0.0], [0.0, 0.0])


def test_anchor_is_the_spring_rest_point_and_shifts_the_solution():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    plant = Plant(a, b, F4, DT, 1000.0)
    anchor = np.array([4.0, -3.0])
    at_rest = np.array([4.0, -3.0, 0.0, 0.0])
    np.testing.assert_allclose(plant.step(at_rest, [0, 0], [0.0], anchor), at_rest, atol=1e-14)
    # Translation equivariance: moving the state and the anchor together moves the result.
    x = np.array([1.0, 2.0, 0.3, -0.1])
    shift = np.array([4.0, -3.0, 0.0, 0.0])
    np.testing.assert_allclose(
        plant.step(x + shift, [3, 1], [0.5], anchor), plant.step(x, [3, 1], [0.5], [0, 0]) + shift, atol=1e-12
    )
    # The spring pulls toward the anchor: velocity after one step points at it.
    v = plant.step(np.array([0.0, 0.0, 0.0, 0.0]), [0, 0], [0.0], anchor)[2:]
    assert v[0] > 0 > v[1]


def test_without_spring_the_anchor_does_not_matter():
    a, b = rover_matrices(40.0, 0.0, 45.0)
    plant = Plant(a, b, F4, DT, 1000.0)
    x = np.array([1.0, 2.0, 0.3, -0.1])
    np.testing.assert_allclose(plant.step(x, [3, 1], [0.5], [10.0, -7.0]), plant.step(x, [3, 1], [0.5], [0, 0]))


def test_disturbance_enters_through_f():
    a, b = rover_matrices(40.0, 0.0, 45.0)
    plant = Plant(a, b, F4, DT, 1000.0)
    dx = plant.step(np.zeros(4), [0, 0], [1.0], [0, 0])
    assert dx[2] < 0 < dx[3] and dx[2] == pytest.approx(-dx[3])
    no_f = Plant(a, b, None, DT, 1000.0)
    assert no_f.q == 0
    np.testing.assert_array_equal(no_f.step(np.ones(4), [0, 0], None, [0, 0]), plant.step(np.ones(4), [0, 0], [0.0], [0, 0]))


@pytest.mark.parametrize(
    'kwargs',
    [
        {'A': np.zeros((3, 4))},
        {'B': np.zeros((3, 2))},
        {'F': np.zeros((2, 1))},
        {'dt': 0.0},
        {'force_limit': 0.0},
    ],
)
def test_bad_construction_raises(kwargs):
    a, b = rover_matrices(40.0, 20.0, 45.0)
    args = {'A': a, 'B': b, 'F': F4, 'dt': DT, 'force_limit': 10.0} | kwargs
    with pytest.raises(ValueError):
        Plant(args['A'], args['B'], args['F'], args['dt'], args['force_limit'])


def test_bad_step_shapes_raise():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    plant = Plant(a, b, F4, DT, 10.0)
    with pytest.raises(ValueError, match='x must'):
        plant.step(np.zeros(3), [0, 0], [0.0], [0, 0])
    with pytest.raises(ValueError, match='u must'):
        plant.step(np.zeros(4), [0, 0, 0], [0.0], [0, 0])
    with pytest.raises(ValueError, match='d must'):
        plant.step(np.zeros(4), [0, 0], [0.0, 1.0], [0, 0])
    with pytest.raises(ValueError, match='anchor'):
        plant.step(np.zeros(4), [0, 0], [0.0], [0, 0, 0])
