"""The half-vectorised Kronecker basis and the time basis."""

import numpy as np

from rrtq_controller.basis import QuadraticBasis, TimeBasis


def test_weights_reproduce_the_quadratic_form():
    rng = np.random.default_rng(0)
    b = QuadraticBasis(4, 2, 1)
    S = rng.normal(size=(7, 7))
    Qbar = S + S.T
    U = rng.normal(size=7)
    w = b.weights_of(Qbar)
    assert b.size == 28
    assert np.isclose(w @ b(U), 0.5 * U @ Qbar @ U)
    assert np.allclose(b.matrix_of(w), Qbar)


def test_learned_pairs_are_those_with_the_state():
    b = QuadraticBasis(4, 2, 1)
    assert b.free.size == 10 + 4 * 2 + 4 * 1
    assert np.all(b.rows[b.fixed] >= 4)
    Qbar = np.zeros((7, 7))
    Qbar[:4, 4:6] = np.arange(8.0).reshape(4, 2)
    Qbar[4:6, :4] = Qbar[:4, 4:6].T
    assert np.allclose(b.cross_block(b.weights_of(Qbar), 'u'), Qbar[4:6, :4])


def test_fixed_blocks_are_the_cost_weights():
    b = QuadraticBasis(4, 2, 1)
    R = np.array([[2.0, 0.3], [0.3, 1.0]])
    w = np.zeros(b.size)
    w[b.fixed] = b.fixed_weights(R, 3.0)
    Q = b.matrix_of(w)
    assert np.allclose(Q[4:6, 4:6], R)
    assert np.isclose(Q[6, 6], -9.0)
    assert np.allclose(Q[4:6, 6], 0.0)


def test_time_basis_starts_constant_and_clips_past_the_horizon():
    tb = TimeBasis((0.0, 1.0, 2.0))
    assert np.allclose(tb(0.0), 1.0)
    assert np.allclose(tb(-3.0), 1.0)
    assert np.allclose(tb(1.0), [1.0, np.exp(-1), np.exp(-2)])
