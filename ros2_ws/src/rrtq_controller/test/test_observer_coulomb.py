"""The observer on a base with Coulomb friction: its model of the linear part stays right.

Ground truth: the plant integrated here at 1 ms (viscous damping c, Coulomb friction F
per axis, sticking at rest while the force is within F), which the observer never sees;
its exact one-step effects over Δt while the velocity keeps its sign are
Φ_vv = e^{-cΔt/m}, Γ_vv = (1 - e^{-cΔt/m}) / c and the friction's -F Γ_vv.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_controller.observer import Observer

DT, MASS, DAMPING = 0.05, 40.0, 45.0
PHI_VV = math.exp(-DAMPING * DT / MASS)
GAMMA_VV = (1.0 - PHI_VV) / DAMPING


def _coulomb_run(friction: float, *, steps: int = 3000, seed: int = 0, disturbance: float = 0.0,
                 gain: tuple[float, float] = (30.0, 60.0), probing: float = 60.0,
                 noise: tuple[float, float] = (0.0, 0.0), delay: int = 0):
    """Legs of 10 s to random targets under a PD gain and probing; (x̄, u, segment) per step.

    ``noise`` (σ_p, σ_v): odometry noise on the x̄ logged and fed back; ``delay``: steps
    before a command acts.
    """
    rng = np.random.default_rng(seed)
    p, v = np.zeros(2), np.zeros(2)
    xs, us, segments = [], [], []
    target = np.zeros(2)
    sub = 50
    h = DT / sub
    pending = [np.zeros(2)] * delay
    sigma = np.repeat(noise, 2)
    for k in range(steps):
        if k % 200 == 0:
            target = rng.uniform(-10.0, 10.0, 2)
        x = np.concatenate([p - target, v])
        if np.any(sigma):
            x = x + sigma * rng.normal(0.0, 1.0, 4)
        u = np.clip(-gain[0] * x[:2] - gain[1] * x[2:] + rng.normal(0.0, probing, 2), -200, 200)
        w = disturbance * MASS * rng.normal(0.0, 1.0, 2) / math.sqrt(DT) * math.sqrt(DT)
        xs.append(x)
        us.append(u)
        segments.append(k // 200)
        pending.append(u)
        acting = pending.pop(0)
        for _ in range(sub):
            for i in range(2):
                force = acting[i] + w[i]
                if v[i] == 0.0 and abs(force) <= friction:
                    continue                                   # stuck
                direction = np.sign(v[i]) if v[i] != 0.0 else np.sign(force)
                new = v[i] + h * (force - DAMPING * v[i] - friction * direction) / MASS
                if v[i] != 0.0 and np.sign(new) != np.sign(v[i]) and abs(force) <= friction:
                    new = 0.0                                  # stops and sticks
                v[i] = new
            p = p + h * v
    return np.array(xs), np.array(us), np.array(segments)


def _model(x, u, segments, velocity, noise=(0.0, 0.0)):
    observer = Observer(4, 2, velocity=velocity)
    observer.variance = np.repeat(np.square(noise), 2)
    for k in range(len(x)):
        observer.record(x[k], u[k], int(segments[k]))
    assert observer.update()
    assert observer.model is not None
    return observer.model


@pytest.mark.parametrize('friction', [39.0, 118.0])
def test_friction_columns_keep_the_linear_part_right(friction):
    x, u, segments = _coulomb_run(friction)
    plain = _model(x, u, segments, None)
    model = _model(x, u, segments, slice(2, 4))
    vv = np.diag(model.phi[2:, 2:])
    gamma = np.diag(model.gamma[2:])
    assert model.friction is not None
    np.testing.assert_allclose(vv, PHI_VV, rtol=0.005)
    np.testing.assert_allclose(gamma, GAMMA_VV, rtol=0.01)
    # the friction's effect over a step, per unit of the input's: -F
    np.testing.assert_allclose(np.diag(model.friction[2:]) / gamma, -friction, rtol=0.03)
    # without the columns the same data give a plant that barely answers its force
    assert np.all(np.abs(np.diag(plain.gamma[2:]) / GAMMA_VV - 1.0) > 0.1)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_without_friction_the_model_is_the_one_without_the_columns(seed):
    x, u, segments = _coulomb_run(0.0, seed=seed, disturbance=0.5)
    model = _model(x, u, segments, slice(2, 4))
    plain = _model(x, u, segments, None)
    assert model.friction is None
    np.testing.assert_allclose(model.phi, plain.phi)
    np.testing.assert_allclose(model.gammas, plain.gammas)


NOISE = (0.02, 0.05)
"""σ_p (m), σ_v (m/s): the odometry noise the robot side must work with (issue 31)."""


def test_under_odometry_noise_and_delay_a_frictionless_plant_gets_no_columns():
    """Errors in variables do not pass for friction.

    The Wald test alone called columns here (seed 5: levels of -1.9 and -0.9 N, a force
    along the motion), as it did on a noisy robot-side run (-15.6 N, and a model with far
    more damping than the plant); friction dissipates (:func:`observer._friction_like`).
    """
    called = []
    for seed in range(10):
        x, u, segments = _coulomb_run(0.0, seed=seed, disturbance=0.5, noise=NOISE, delay=2)
        model = _model(x, u, segments, slice(2, 4), NOISE)
        if model.friction is not None:
            called.append((seed, model.friction_level))
        np.testing.assert_allclose(np.diag(model.phi[2:, 2:]), PHI_VV, atol=0.01)
    assert called == []


def test_under_odometry_noise_and_delay_friction_is_still_identified():
    """The level within 10 %; Γ within 15 %, low: under noise the transitions in which
    friction holds the robot cannot be told from slow ones (at rest is within 2.6 σ_v) and
    are fitted, and they show no effect of the force (Γ 6 % and 13 % low here; within
    1 % with exact odometry, where they are left out)."""
    x, u, segments = _coulomb_run(39.0, disturbance=0.5, noise=NOISE, delay=2)
    model = _model(x, u, segments, slice(2, 4), NOISE)
    assert model.friction_level is not None
    np.testing.assert_allclose(model.friction_level, 39.0, rtol=0.1)
    np.testing.assert_allclose(np.diag(model.gamma[2:]), GAMMA_VV, rtol=0.15)


def test_a_robot_friction_holds_still_gives_no_model():
    """Forces within the friction never move it: no transition shows what a force does."""
    x, u, segments = _coulomb_run(500.0, gain=(0.0, 0.0), probing=60.0)
    assert np.all(x[:, 2:] == 0.0)
    observer = Observer(4, 2, velocity=slice(2, 4))
    for k in range(len(x)):
        observer.record(x[k], u[k], int(segments[k]))
    assert not observer.update()
    assert observer.model is None


@pytest.mark.parametrize('friction', [39.0, 118.0])
def test_the_friction_level_and_its_lower_bound(friction):
    """The level per axis within 3 % of F, its lower 99 % bound below F and above 0.9 F."""
    x, u, segments = _coulomb_run(friction)
    observer = Observer(4, 2, velocity=slice(2, 4))
    for k in range(len(x)):
        observer.record(x[k], u[k], int(segments[k]))
    assert observer.update()
    model = observer.model
    assert model is not None and model.friction_level is not None
    np.testing.assert_allclose(model.friction_level, friction, rtol=0.03)
    bound = observer.friction()
    assert bound is not None
    assert np.all(bound <= model.friction_level) and np.all(bound > 0.9 * friction)


@pytest.mark.parametrize('on', [True, False])
def test_the_controller_compensates_the_identified_friction(on):
    """Along a moving axis the level in the direction of motion, along one at rest in the
    force's; nothing with ``friction_compensation: false`` or before friction is identified."""
    from rrtq_controller.config import ControllerConfig
    from rrtq_controller.q_learning import QLearningController

    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, friction_compensation=on)
    controller = QLearningController(config, 4, 2, 0, np.random.default_rng(0))
    observer = controller.observer
    assert observer is not None and observer.velocity == slice(2, 4)
    x = np.array([1.0, -1.0, 0.5, 0.0])           # moving +x, y at rest
    u = np.array([-10.0, 20.0])
    assert np.all(controller._friction_force(u, x) == 0.0)      # nothing identified yet
    xs, us, segments = _coulomb_run(118.0)
    for k in range(len(xs)):
        observer.record(xs[k], us[k], int(segments[k]))
    assert observer.update()
    level = observer.friction()
    assert level is not None
    expected = level * np.array([1.0, 1.0]) if on else np.zeros(2)
    np.testing.assert_allclose(controller._friction_force(u, x), expected)
    np.testing.assert_allclose(controller._friction_force(-u, x),
                               level * np.array([1.0, -1.0]) if on else np.zeros(2))


def test_integral_action_and_compensation_count_the_friction_once():
    from rrtq_controller.q_learning import _overcome

    held, friction = np.array([150.0, -30.0, 20.0, 0.0]), np.array([118.0, 118.0, -118.0, 40.0])
    np.testing.assert_allclose(_overcome(held, friction), [150.0, 88.0, -98.0, 40.0])
    np.testing.assert_allclose(_overcome(np.zeros(2), np.array([5.0, -5.0])), [5.0, -5.0])
    np.testing.assert_allclose(_overcome(np.array([5.0, -5.0]), np.zeros(2)), [5.0, -5.0])
