"""The controller's ground truth (:mod:`rrtq_testing.controller_reference`) against
independent facts: the algebraic Riccati equation, the game bound, fine quadrature."""

import numpy as np
from scipy.linalg import solve_continuous_are

from rrtq_testing.controller_reference import (MAXWELL_SLIP_F, game_gamma_bound, riccati, rover,
                                               zoh, zoh_cost)


def test_riccati_tends_to_the_algebraic_solution():
    A, B = rover(stiffness=0.0)
    M, R = 10.0 * np.eye(4), 0.02 * np.eye(2)
    P = riccati(A, B, M, R, 0.5 * np.eye(4), 40.0)
    assert np.allclose(P(40.0), solve_continuous_are(A, B, M, R), rtol=1e-6)
    assert np.allclose(P(0.0), 0.5 * np.eye(4))


def test_gamma_bound_separates_escape_from_existence():
    A, B = rover(stiffness=0.0)
    M, R, P_T = 10.0 * np.eye(4), 0.02 * np.eye(2), 0.5 * np.eye(4)
    g = game_gamma_bound(A, B, M, R, P_T, 10.0, MAXWELL_SLIP_F)
    riccati(A, B, M, R, P_T, 10.0, MAXWELL_SLIP_F, 1.01 * g)
    try:
        riccati(A, B, M, R, P_T, 10.0, MAXWELL_SLIP_F, 0.99 * g)
    except FloatingPointError:
        return
    raise AssertionError('no finite escape below the bound')


def test_zoh_cost_matches_fine_quadrature():
    A, B = rover()
    Qc = np.diag([10.0, 10, 10, 10, 2, 2])
    Qd = zoh_cost(A, B, Qc, 0.05)
    x, u = np.array([1.0, -2, 0.5, 0.3]), np.array([3.0, -1])
    Ad, Bd = zoh(A, B, 0.05 / 1000)
    acc, xs = 0.0, x.copy()
    for _ in range(1000):
        x1 = Ad @ xs + Bd @ u
        z0, z1 = np.concatenate([xs, u]), np.concatenate([x1, u])
        acc += 0.5 * (z0 @ Qc @ z0 + z1 @ Qc @ z1) * 0.05 / 1000
        xs = x1
    z = np.concatenate([x, u])
    assert abs(z @ Qd @ z - acc) < 1e-6 * acc
