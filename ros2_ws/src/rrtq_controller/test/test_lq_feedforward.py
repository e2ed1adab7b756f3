"""The LQ-optimal push feed-forward (``rrtq_controller.push_feedforward``).

Ground truth: the discrete Riccati solution of the *augmented* plant (robot and push model
in one state) from scipy, and the true plant's exact zero-order-hold discretisation with the
push it is given (``rrtq_testing.controller_reference``); the feed-forward sees only the
odometry, its forces and what the observer identifies from them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from rrtq_controller.observer import Observer
from rrtq_controller.push_feedforward import PushFeedforward, feedforward_gain, internal_model
from rrtq_testing import controller_reference as ref

DT = 0.05
F = ref.MAXWELL_SLIP_F
MASS = 40.0
M = 10.0 * np.eye(4)
R = 0.02 * np.eye(2)


def _rover(stiffness: float = 0.0):
    A, B = ref.rover(MASS, stiffness, 45.0)
    return ref.zoh(A, B, DT)


def _riccati_gain(phi, gamma):
    P = solve_discrete_are(phi, gamma, M * DT, R * DT)
    return np.linalg.solve(R * DT + gamma.T @ P @ gamma, gamma.T @ P @ phi)


@pytest.mark.parametrize('stiffness', [0.0, 20.0])
def test_the_gain_is_the_augmented_riccati_gain(stiffness):
    """With a damped push model (so that the augmented problem has a Riccati solution) K_ω
    is the push's columns of the gain of the robot and push taken as one plant."""
    phi, gamma = _rover(stiffness)
    w = 2 * math.pi * 0.1 * DT
    A, G = internal_model(np.array([2 * 0.97 * math.cos(w), -0.97 ** 2]), 2)
    A[:2, :2] *= 0.97                                   # the constant decays a little too
    q = A.shape[0]
    big_phi = np.block([[phi, gamma @ G], [np.zeros((q, 4)), A]])
    big_gamma = np.vstack([gamma, np.zeros((q, 2))])
    big_M = np.zeros((4 + q, 4 + q))
    big_M[:4, :4] = M
    big_M[4:, 4:] = 1e-6 * np.eye(q)   # the push's own cost: it moves P's push block only
    P = solve_discrete_are(big_phi, big_gamma, big_M * DT, R * DT)
    big_K = np.linalg.solve(R * DT + big_gamma.T @ P @ big_gamma, big_gamma.T @ P @ big_phi)
    np.testing.assert_allclose(big_K[:, :4], _riccati_gain(phi, gamma), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(feedforward_gain(phi, gamma, M, R, DT, A, G), big_K[:, 4:],
                               rtol=1e-6, atol=1e-9)


def test_a_steady_push_is_met_whole_by_a_robot_without_a_spring():
    phi, gamma = _rover()
    A, G = internal_model(np.zeros(0), 2)
    np.testing.assert_allclose(feedforward_gain(phi, gamma, M, R, DT, A, G), np.eye(2),
                               atol=1e-9)


def _fly(kind: str, law: str, *, seed: int = 0, seconds: float = 60.0):
    """The Riccati feedback of the identified model on the true rover, 150 s of probed legs
    for the observer, then ``seconds`` holding station under the push; returns the LQ cost
    rate there (per second), the robot's largest offset over the last 10 s and the RMS
    feed-forward (N)."""
    A_c, B_c = ref.rover(MASS, 0.0, 45.0)
    plant = ref.Plant(A_c, B_c, DT, F)
    rng = np.random.default_rng(seed)
    observer = Observer(4, 2, lags=3, memory=4000, reads_pushes=True)
    forward = PushFeedforward(2, DT, M, R, 0.01)
    K_pd = np.array([[40.0, 0.0, 30.0, 0.0], [0.0, 40.0, 0.0, 30.0]])
    a = math.exp(-DT)
    probe = np.zeros(2)
    x = np.zeros(4)
    learn = int(150.0 / DT)
    K = K_pd
    cost, offset, ff_power, count = 0.0, 0.0, 0.0, 0
    for k in range(learn + int(seconds / DT)):
        t = k * DT
        d = {'steady': 0.5, 'sinusoid': 0.5 * math.sin(2 * math.pi * 0.1 * t),
             'white': 0.5 * rng.standard_normal()}[kind]
        if k < learn and k % 200 == 0:
            x = np.concatenate([ref.random_legs(rng, 1, 2.0, 8.0)[0], x[2:]])
        if k == learn:
            x = np.concatenate([np.zeros(2), x[2:]])
            assert observer.update() and observer.model is not None
            model = observer.model
            K = _riccati_gain(model.phi, model.gamma)
            forward.fit(model.phi, model.gamma, model.ar, observer.pushes(), np.zeros((2, 2)),
                        model.delay + 1)
        if k > 0 and (k < learn and k % 200 != 0 or k > learn):
            forward.update(observer.last_push(x) if k > learn else None)
        probe = a * probe + math.sqrt(1 - a * a) * 20.0 * rng.standard_normal(2)
        ff = np.zeros(2)
        if k >= learn:
            if law == 'optimal':
                ff = forward.force()
            elif law == 'cancel':
                ff = -MASS * d * F[2:, 0]            # the whole push, known exactly
        u = -K @ x + (probe if k < learn else 0.0) + ff
        observer.record(x, u, k // 200 if k < learn else -1)
        if k >= learn:
            cost += (x @ M @ x + u @ R @ u) * DT
            if k >= learn + int((seconds - 10.0) / DT):       # the last 10 s
                offset = max(offset, float(np.hypot(*x[:2])))
            ff_power += float(ff @ ff)
            count += 1
        x = plant.step(x, u, np.array([d]))
    return cost / seconds, offset, math.sqrt(ff_power / max(count, 1) / 2)


def test_a_steady_push_no_longer_holds_the_robot_short():
    none = _fly('steady', 'none')
    optimal = _fly('steady', 'optimal')
    assert none[1] > 0.5                      # the feedback alone: 20 N / K_p short
    assert optimal[1] < 0.05 * none[1]
    assert optimal[0] < 0.6 * none[0]


def test_a_periodic_push_costs_less_than_the_feedback_alone_and_than_cancelling_it():
    none, cancel, optimal = (_fly('sinusoid', law) for law in ('none', 'cancel', 'optimal'))
    assert cancel[0] > none[0]                # the whole push spent on: dearer than nothing
    assert optimal[0] < 0.7 * none[0]


def test_a_white_push_is_not_fed_forward():
    none, optimal = _fly('white', 'none'), _fly('white', 'optimal')
    assert optimal[2] < 0.1 * MASS * 0.5      # N RMS, against the push's 20 N RMS
    assert optimal[0] < 1.05 * none[0]
