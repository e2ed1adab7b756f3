"""Riccati ground truth: checked against closed forms, the algebraic Riccati equation
and the Hamiltonian (linear) representation of the Riccati flow."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm, solve_continuous_are

from rrtq_sim.plant import rover_matrices
from rrtq_sim.riccati import RiccatiEscape, game_gamma_bound, solve_riccati

F4 = np.array([[0.0], [0.0], [-1.0], [1.0]])


def hamiltonian_p(a, s, m, p_t, tau):
    """P(tau) = Y X^-1 with [X; Y]' = [[-A, S], [M, A^T]] [X; Y], X(0) = I, Y(0) = P_T."""
    n = a.shape[0]
    h = np.block([[-a, s], [m, a.T]])
    xy = expm(h * tau) @ np.vstack((np.eye(n), p_t))
    return xy[n:] @ np.linalg.inv(xy[:n])


def scalar_lqr(a, b, m, r, p0, tau):
    """Closed form of p' = 2 a p + m - (b^2 / r) p^2, p(0) = p0."""
    s = b * b / r
    root = math.sqrt(a * a + s * m)
    p1, p2 = (a + root) / s, (a - root) / s  # p' = -s (p - p1)(p - p2)
    c = (p0 - p1) / (p0 - p2) * math.exp(-s * (p1 - p2) * tau)
    return (p1 - c * p2) / (1.0 - c)


@pytest.mark.parametrize('tau', [0.0, 0.3, 1.0, 4.0])
def test_scalar_lqr_matches_closed_form(tau):
    sol = solve_riccati([[1.0]], [[2.0]], [[3.0]], [[0.5]], [[0.2]], 4.0)
    assert sol.P(tau)[0, 0] == pytest.approx(scalar_lqr(1.0, 2.0, 3.0, 0.5, 0.2, tau), rel=1e-9)


def test_rover_lqr_converges_to_care_for_long_horizon():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    m, r = 10.0 * np.eye(4), 0.02 * np.eye(2)
    sol = solve_riccati(a, b, m, r, 0.5 * np.eye(4), 60.0)
    care = solve_continuous_are(a, b, m, r)
    np.testing.assert_allclose(sol.P(60.0), care, rtol=1e-6)
    np.testing.assert_allclose(sol.gain(60.0), np.linalg.solve(r, b.T @ care), rtol=1e-6)
    # Far from the horizon end it is not yet stationary: the check can fail.
    assert not np.allclose(sol.P(0.5), care, rtol=1e-2)


def test_unstable_lqr_matches_hamiltonian_solution():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(3, 3)) + 0.5 * np.eye(3)
    b = rng.normal(size=(3, 2))
    m, r, p_t = np.eye(3), np.diag([0.5, 2.0]), 0.1 * np.eye(3)
    sol = solve_riccati(a, b, m, r, p_t, 3.0)
    s = b @ np.linalg.solve(r, b.T)
    for tau in (0.25, 1.0, 3.0):
        np.testing.assert_allclose(sol.P(tau), hamiltonian_p(a, s, m, p_t, tau), rtol=1e-8, atol=1e-10)


def test_game_matches_hamiltonian_and_augmented_care():
    a, b = rover_matrices(40.0, 0.0, 45.0)
    m, r, p_t, gamma = 10.0 * np.eye(4), 0.02 * np.eye(2), 0.5 * np.eye(4), 12.0
    sol = solve_riccati(a, b, m, r, p_t, 40.0, F4, gamma)
    s = b @ np.linalg.solve(r, b.T) - F4 @ F4.T / gamma**2
    np.testing.assert_allclose(sol.P(2.0), hamiltonian_p(a, s, m, p_t, 2.0), rtol=1e-8)
    # Stationary game: the ARE with the disturbance as a second player of weight -gamma^2.
    care = solve_continuous_are(a, np.hstack((b, F4)), m, np.diag([0.02, 0.02, -(gamma**2)]))
    np.testing.assert_allclose(sol.P(40.0), care, rtol=1e-6)
    # The disturbance raises the cost over plain LQR.
    lqr = solve_riccati(a, b, m, r, p_t, 40.0)
    excess = np.linalg.eigvalsh(sol.P(40.0) - lqr.P(40.0))
    assert excess.min() > -1e-8 and excess.max() > 1.0


def test_gains_solution_shape_symmetry_and_clipping():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    r = 2.0 * np.eye(2)
    sol = solve_riccati(a, b, 10.0 * np.eye(4), r, 0.5 * np.eye(4), 10.0, F4, 20.0)
    p = sol.P(3.0)
    assert p.shape == (4, 4) and np.array_equal(p, p.T)
    np.testing.assert_allclose(sol.gain(3.0), np.linalg.inv(r) @ b.T @ p)
    np.testing.assert_allclose(sol.disturbance_gain(3.0), F4.T @ p / 400.0)
    np.testing.assert_allclose(sol(3.0), p)
    np.testing.assert_allclose(sol.P(-5.0), 0.5 * np.eye(4), atol=1e-14)
    np.testing.assert_array_equal(sol.P(99.0), sol.P(10.0))
    with pytest.raises(ValueError):
        solve_riccati(a, b, np.eye(4), r, np.eye(4), 1.0).disturbance_gain(0.0)


def test_finite_escape_is_detected_at_the_right_time():
    # No control (B = 0), p' = p^2 / gamma^2 with p(0) = 1, gamma = 1: p = 1 / (1 - tau).
    args = ([[0.0]], [[0.0]], [[0.0]], [[1.0]], [[1.0]])
    sol = solve_riccati(*args, 0.9, [[1.0]], 1.0)
    assert sol.P(0.9)[0, 0] == pytest.approx(10.0, rel=1e-8)
    with pytest.raises(RiccatiEscape) as info:
        solve_riccati(*args, 2.0, [[1.0]], 1.0)
    assert info.value.tau == pytest.approx(1.0, abs=1e-6)


def test_scalar_gamma_bound_matches_closed_form():
    # a = m = 0: p' = -s p^2 with s = b^2/r - f^2/gamma^2; escape within T iff -s p0 T >= 1,
    # so gamma* = f / sqrt(b^2 / r + 1 / (p0 T)).
    bound = game_gamma_bound([[0.0]], [[1.0]], [[0.0]], [[1.0]], [[1.0]], 1.0, [[1.0]], tol=1e-5)
    assert bound == pytest.approx(1.0 / math.sqrt(2.0), abs=2e-5)


def test_rover_gamma_bound_separates_bounded_from_escaping():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    m, r, p_t, horizon = 10.0 * np.eye(4), 2.0 * np.eye(2), 0.5 * np.eye(4), 5.0
    bound = game_gamma_bound(a, b, m, r, p_t, horizon, F4, tol=1e-3)
    assert 1.0 < bound < 100.0
    solve_riccati(a, b, m, r, p_t, horizon, F4, bound * 1.002)
    with pytest.raises(RiccatiEscape):
        solve_riccati(a, b, m, r, p_t, horizon, F4, bound * 0.998)


def test_gamma_bound_is_zero_without_disturbance_channel():
    a, b = rover_matrices(40.0, 20.0, 45.0)
    assert game_gamma_bound(a, b, np.eye(4), np.eye(2), np.eye(4), 2.0, np.zeros((4, 1)), tol=1e-2) == 0.0


def test_inputs_are_validated():
    with pytest.raises(ValueError, match='together'):
        solve_riccati([[0.0]], [[1.0]], [[1.0]], [[1.0]], [[1.0]], 1.0, F=[[1.0]])
    with pytest.raises(ValueError, match='R must'):
        solve_riccati([[0.0]], [[1.0]], [[1.0]], np.eye(2), [[1.0]], 1.0)
    with pytest.raises(ValueError, match='T must'):
        solve_riccati([[0.0]], [[1.0]], [[1.0]], [[1.0]], [[1.0]], 0.0)
