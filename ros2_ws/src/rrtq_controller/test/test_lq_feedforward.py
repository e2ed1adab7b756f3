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
from rrtq_controller.push_feedforward import (PushFeedforward, feedforward_gain, find_harmonic,
                                              internal_model)
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
    A, G = internal_model(2 * math.pi * 0.1 * DT, 2, decay=0.97)   # stabilisable
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
    A, G = internal_model(None, 2)
    np.testing.assert_allclose(feedforward_gain(phi, gamma, M, R, DT, A, G), np.eye(2),
                               atol=1e-9)


def _fly(kind: str, law: str, *, seed: int = 0, seconds: float = 60.0,
         odometry: tuple[float, float] = (0.0, 0.0), delay: int = 0):
    """The Riccati feedback of the identified model on the true rover, 150 s of probed legs
    for the observer, then ``seconds`` holding station under the push; returns the LQ cost
    rate there (per second), the robot's largest offset over the last 10 s and the RMS
    feed-forward (N). ``odometry``: the position and velocity noise (m, m/s, the observer
    told their variances as a robot's odometry reports them); ``delay``: steps before a
    force acts."""
    A_c, B_c = ref.rover(MASS, 0.0, 45.0)
    plant = ref.Plant(A_c, B_c, DT, F)
    rng = np.random.default_rng(seed)
    sensor = np.random.default_rng(seed + 1000)
    sigma = np.repeat(np.asarray(odometry, dtype=float), 2)
    observer = Observer(4, 2, lags=3, memory=4000, reads_pushes=True)
    observer.variance = np.square(sigma)
    forward = PushFeedforward(2, DT, M, R, 0.01)
    K_pd = np.array([[40.0, 0.0, 30.0, 0.0], [0.0, 40.0, 0.0, 30.0]])
    a = math.exp(-DT)
    probe = np.zeros(2)
    x = np.zeros(4)
    acting = [np.zeros(2)] * delay
    learn = int(150.0 / DT)
    K = K_pd
    cost, offset, ff_power, count = 0.0, 0.0, 0.0, 0
    for k in range(learn + int(seconds / DT)):
        t = k * DT
        d = {'none': 0.0, 'steady': 0.5, 'sinusoid': 0.5 * math.sin(2 * math.pi * 0.1 * t),
             'white': 0.5 * rng.standard_normal()}[kind]
        if k < learn and k % 200 == 0:
            x = np.concatenate([ref.random_legs(rng, 1, 2.0, 8.0)[0], x[2:]])
        if k == learn:
            x = np.concatenate([np.zeros(2), x[2:]])
            assert observer.update() and observer.model is not None
            model = observer.model
            assert model.delay == delay
            K = _riccati_gain(model.phi, model.gamma)
        y = x + sigma * sensor.standard_normal(4)
        if k == learn:
            forward.fit(model.phi, model.gamma, observer.pushes(), observer.read_noise(),
                        model.delay + 1)
        if k > 0 and (k < learn and k % 200 != 0 or k > learn):
            forward.update(observer.last_push(y) if k > learn else None)
        probe = a * probe + math.sqrt(1 - a * a) * 20.0 * rng.standard_normal(2)
        ff = np.zeros(2)
        if k >= learn:
            if law == 'optimal':
                ff = forward.force()
            elif law == 'cancel':
                ff = -MASS * d * F[2:, 0]            # the whole push, known exactly
        u = -K @ y + (probe if k < learn else 0.0) + ff
        observer.record(y, u, k // 200 if k < learn else -1)
        if k >= learn:
            cost += (x @ M @ x + u @ R @ u) * DT
            if k >= learn + int((seconds - 10.0) / DT):       # the last 10 s
                offset = max(offset, float(np.hypot(*x[:2])))
            ff_power += float(ff @ ff)
            count += 1
        acting.append(u)
        x = plant.step(x, acting.pop(0), np.array([d]))
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


NOISY = {'odometry': (0.02, 0.05), 'delay': 2}
"""The robot-side benchmark's noisy row: a read then carries ~50 N RMS of noise against the
push's 20 N."""


def test_under_odometry_noise_and_delay_a_periodic_push_is_still_predicted():
    """The AR fit of the observer takes noisy reads of a 0.1 Hz sinusoid for near white
    ((0.78, 0.17) against (2.0, -1.0)) and predicted nothing of it (cost 1.01-1.04 x the
    feedback alone); the harmonic the periodogram finds is fed forward."""
    none, optimal = _fly('sinusoid', 'none', **NOISY), _fly('sinusoid', 'optimal', **NOISY)
    assert optimal[0] < 0.75 * none[0]
    assert optimal[2] > 0.3 * MASS * 0.5 / math.sqrt(2)    # a share of the push's 14 N RMS


@pytest.mark.parametrize('kind', ['none', 'white'])
def test_under_odometry_noise_nothing_is_fed_forward_without_a_predictable_push(kind):
    none, optimal = _fly(kind, 'none', **NOISY), _fly(kind, 'optimal', **NOISY)
    assert optimal[2] < 0.5                                  # N RMS
    assert optimal[0] < 1.02 * none[0]


def _reads(rng, count, amplitude, noise, hertz=0.1, gaps=True):
    """``count`` reads (N, two inputs) of a harmonic in white noise at step ids with gaps (the
    observer keeps braked steps and leg switches out)."""
    steps = np.arange(int(count * 1.2))
    if gaps:
        steps = np.sort(rng.choice(steps, count, replace=False))
    else:
        steps = steps[:count]
    phase = rng.uniform(0, 2 * math.pi, 2)
    push = amplitude * np.sin(2 * math.pi * hertz * DT * steps[:, None] + phase)
    return push + noise * rng.standard_normal((count, 2)), steps


def test_the_harmonic_is_found_in_noisy_reads_to_its_resolution():
    rng = np.random.default_rng(3)
    for _ in range(5):
        push, steps = _reads(rng, 4000, 20.0, 53.0)
        omega = find_harmonic(push, steps, 0.01)
        assert omega is not None
        resolution = 1.0 / (steps[-1] - steps[0] + 1)          # cycles per step
        assert abs(omega / (2 * math.pi) - 0.1 * DT) < resolution


@pytest.mark.parametrize('colour', ['white', 'odometry'])
def test_noise_shows_a_harmonic_at_most_at_the_stated_false_alarm_rate(colour):
    """α = 1 % in each half, so the rate of a false harmonic is at most 1 %: 300 trials of
    reads without a push, of which more than 9 would happen with probability 0.004 at 1 %.
    ``odometry``: a read's noise is a difference of the odometry's, n_{k+1} - 0.9 n_k, whose
    spectrum rises toward the Nyquist frequency (against white noise's level it showed a
    "harmonic" there in most trials)."""
    rng = np.random.default_rng(4)
    found = 0
    for _ in range(300):
        n = 53.0 * rng.standard_normal((1001, 2))
        noise = n[1:] - 0.9 * n[:-1] if colour == 'odometry' else n[1:]
        found += find_harmonic(noise, np.sort(rng.choice(1200, 1000, replace=False)),
                               0.01) is not None
    assert found <= 9


def test_a_push_felt_once_is_not_taken_for_a_harmonic():
    """A field crossed once (15 s of a 28 N push in 200 s of reads): power at low frequencies,
    in one half only."""
    steps = np.arange(4000)
    push = np.zeros((4000, 2))
    push[2600:2900] = (28.0, -28.0)
    rng = np.random.default_rng(5)
    assert find_harmonic(push + 2.0 * rng.standard_normal((4000, 2)), steps, 0.01) is None
