"""The position-dependent disturbance field against values worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_sim.field import (Bump, DisturbanceField, bump_profile, compose_input_matrix,
                            field_input_matrix)
from rrtq_sim.plant import Plant, rover_matrices


def test_profile_is_one_at_the_centre_and_zero_from_the_radius_on():
    s = np.array([0.0, 0.5, 0.999, 1.0, 1.5, -0.5])
    expected = [1.0, math.exp(1 - 1 / 0.75), math.exp(1 - 1 / (1 - 0.999**2)), 0.0, 0.0,
                math.exp(1 - 1 / 0.75)]
    np.testing.assert_allclose(bump_profile(s), expected, rtol=1e-12, atol=1e-300)


def test_bumps_add_up_and_vanish_outside_their_discs():
    field = DisturbanceField([Bump((0.0, 0.0), 2.0, (1.0, -0.5)),
                              Bump((3.0, 0.0), 2.0, (0.0, 2.0))])
    np.testing.assert_allclose(field.acceleration([0.0, 0.0]), [1.0, -0.5])
    # Halfway between the centres (1.5 m from each, s = 0.75): both contribute.
    b = math.exp(1 - 1 / (1 - 0.75**2))
    np.testing.assert_allclose(field.acceleration([1.5, 0.0]), [b, -0.5 * b + 2.0 * b])
    np.testing.assert_array_equal(field.acceleration([[10.0, 10.0], [-2.0, 0.0]]),
                                  np.zeros((2, 2)))
    # A full state is accepted (only the position is read); shapes follow the input.
    assert field.acceleration(np.zeros((3, 5, 4))).shape == (3, 5, 2)
    assert field.peak() == pytest.approx(math.hypot(1.0, 0.5) + 2.0)
    # The field is radially symmetric about each centre.
    ang = np.linspace(0, 2 * np.pi, 9)
    ring = 1.2 * np.column_stack([np.cos(ang), np.sin(ang)])
    one = DisturbanceField([Bump((0.0, 0.0), 2.0, (1.0, 0.0))])
    np.testing.assert_allclose(one.acceleration(ring)[:, 0], bump_profile(0.6) * np.ones(9))


def test_bad_bumps_are_rejected():
    with pytest.raises(ValueError, match='radius'):
        Bump((0.0, 0.0), 0.0, (1.0, 1.0))
    with pytest.raises(ValueError, match='value'):
        Bump((0.0, 0.0), 1.0, (1.0, float('nan')))
    with pytest.raises(ValueError, match='n >= 4'):
        field_input_matrix(2)


def test_composed_plant_applies_the_field_as_an_acceleration():
    # A frictionless double integrator: one ZOH step under a constant acceleration a moves
    # the robot by a dt²/2 and changes its velocity by a dt, whatever the time model adds.
    a_mat, b_mat = rover_matrices(40.0, 0.0, 0.0)
    f_time = np.array([[0.0], [0.0], [-1.0], [1.0]])
    dt = 0.1
    plant = Plant(a_mat, b_mat, compose_input_matrix(f_time, 4), dt, 1000.0)
    field = DisturbanceField([Bump((0.0, 0.0), 5.0, (0.6, -0.2))])
    x = np.array([0.0, 0.0, 0.3, 0.0])
    d_time = 0.25
    a = field.acceleration(x)
    x1 = plant.step(x, np.zeros(2), np.concatenate([[d_time], a]), np.zeros(2))
    acc = a + d_time * f_time[2:, 0]
    np.testing.assert_allclose(x1[:2], x[:2] + x[2:] * dt + 0.5 * acc * dt**2, atol=1e-12)
    np.testing.assert_allclose(x1[2:], x[2:] + acc * dt, atol=1e-12)
