"""The guard's rollout test: a policy read through the identified model, not its critic.

Ground truth: the finite-horizon Riccati gain of the true rover (scipy, through
``rrtq_testing.controller_reference``), exact zero-order-hold matrices (``expm``), and a
step-by-step simulation of the delayed loop written out here.
"""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from rrtq_controller.observer import OneStepModel
from rrtq_controller.rollout import carries_away, closed_loop, worst_growth
from rrtq_testing import controller_reference as ref

DT, T = 0.05, 10.0
M, R, P_T = 10.0 * np.eye(4), 0.02 * np.eye(2), 0.5 * np.eye(4)
STARTS = np.linspace(T, DT, 8)


def model(delay: int, lags: int = 3, stiffness: float = 0.0) -> OneStepModel:
    """The exact one-step model of the rover, its force acting ``delay`` steps late."""
    A, B = ref.rover(stiffness=stiffness)
    E = expm(np.block([[A, B], [np.zeros((2, 6))]]) * DT)
    gammas = np.zeros((lags + 1, 4, 2))
    gammas[delay] = E[:4, 4:]
    return OneStepModel(E[:4, :4], gammas, np.zeros(0), np.eye(4))


def riccati_gain(stiffness: float = 0.0):
    A, B = ref.rover(stiffness=stiffness)
    P = ref.riccati(A, B, M, R, P_T, T)
    return lambda tau: np.linalg.solve(R, B.T @ P(tau))


def flipped_gain():
    """The Riccati gain with the y position gain turning negative below 5 s to go."""
    optimum = riccati_gain()

    def flipped(tau):
        K = optimum(tau).copy()
        K[1, 1] *= np.clip((tau - 5.0) / 2.0, -2.0, 1.0)
        return K
    return flipped


@pytest.mark.parametrize('delay', [0, 2])
def test_the_riccati_policy_only_closes_the_offset(delay):
    away = carries_away(model(delay), riccati_gain(), T, DT, STARTS)
    assert away.excess <= 1e-12, away                # never farther than standing still


def test_no_force_is_standing_still():
    away = carries_away(model(2), lambda tau: np.zeros((2, 4)), T, DT, STARTS)
    assert away.growth == pytest.approx(1.0) and away.excess == pytest.approx(0.0, abs=1e-12)


def test_a_position_gain_that_turns_negative_mid_horizon_carries_the_robot_away():
    # The pattern the critic proposed under noisy odometry and a 2-step delay: the y
    # position gain positive early in the leg, negative below 5 s to go.
    away = carries_away(model(2), flipped_gain(), T, DT, STARTS)
    assert away.excess > 1.0, away                   # beyond twice standing still: diverged
    assert away.start < 5.0 + 2.0 and away.tau < away.start
    assert 'carries a robot at rest' in str(away)


def test_the_closed_loop_matrices_are_the_delayed_loop_step_by_step():
    rng = np.random.default_rng(0)
    m2 = model(2)
    gains = rng.normal(0.0, 5.0, (30, 2, 4))
    x, past = np.array([1.0, -0.5, 0.2, 0.0]), [np.zeros(2)] * 3     # u_{k-1..k-3}
    z = np.concatenate([x, *past])
    for K, Tk in zip(gains, closed_loop(m2, gains), strict=True):
        u = -K @ x
        forces = [u, *past]
        x = m2.phi @ x + sum(m2.gammas[j] @ forces[j] for j in range(4))
        past = forces[:3]
        z = Tk @ z
        assert np.allclose(z, np.concatenate([x, *past]), atol=1e-9)


def test_worst_growth_is_the_position_blocks_norm_from_rest():
    m0 = model(0, lags=0)
    K = np.tile(np.array([[4.0, 0.0, 3.0, 0.0], [0.0, 1.0, 0.0, 3.0]]), (40, 1, 1))
    growth = worst_growth(closed_loop(m0, K), 2, 0)
    step = m0.phi - m0.gammas[0] @ K[0]
    power = np.eye(4)
    for k in range(40):
        power = step @ power
        assert growth[k] == pytest.approx(np.linalg.norm(power[:2, :2], 2))


def weights_of(ctrl, gain):
    """The actor weights (L n x m) whose K̂(τ) is ``gain`` in the controller's time basis."""
    taus = np.linspace(0.0, T, 81)
    phi = ctrl.time_basis.batch(taus)
    target = np.array([-gain(t).T.ravel() for t in taus])      # -K(τ)ᵀ = Σ φ_l W_l
    W = np.linalg.lstsq(phi, target, rcond=None)[0]
    return W.reshape(-1, 2)


@pytest.mark.parametrize('on', [True, False])
def test_the_guard_rejects_a_proposal_that_carries_the_robot_away(on):
    from rrtq_controller.config import ControllerConfig
    from rrtq_controller.q_learning import QLearningController
    ctrl = QLearningController(ControllerConfig(rollout_test=on), 4, 2, 0,
                               np.random.default_rng(0))
    assert ctrl.observer is not None
    assert ctrl._carries_away(weights_of(ctrl, riccati_gain())) is None   # no model yet
    ctrl.observer.model = model(2)
    optimum, flipped = riccati_gain(), flipped_gain()
    W = weights_of(ctrl, optimum)
    assert np.allclose(ctrl.gain(3.0, W), optimum(3.0), atol=0.05 * np.abs(optimum(3.0)).max())
    assert ctrl._carries_away(W) is None
    away = ctrl._carries_away(weights_of(ctrl, flipped))
    assert (away is not None) is on
    if on:
        assert away.excess > ctrl.config.divergence_distance - 1.0
        # an escalation is judged against the policy in use: from the flipped one, the same
        # proposal is no worse and passes
        ctrl._target = (weights_of(ctrl, flipped), ctrl._target[1])
        assert ctrl._carries_away(weights_of(ctrl, flipped)) is None


def test_a_greedy_gain_that_carries_the_robot_away_is_held_where_it_starts_to():
    # The critic's greedy gain with the flip below 5 s to go: held at its value above the
    # flip it carries no robot away, and where it did not misbehave it is unchanged.
    from rrtq_controller.config import ControllerConfig
    from rrtq_controller.q_learning import QLearningController
    ctrl = QLearningController(ControllerConfig(), 4, 2, 0, np.random.default_rng(0))
    ctrl.observer.model = model(2)
    optimum, flipped = riccati_gain(), flipped_gain()
    W = weights_of(ctrl, flipped)
    before = carries_away(model(2), lambda t: ctrl.gain(t, W), T, DT, STARTS)
    held = ctrl._held_where_away(W, 0.0)
    after = carries_away(model(2), lambda t: ctrl.gain(t, held), T, DT, STARTS)
    assert before.excess > 1.0 and after.excess < 0.2 * before.excess, (before, after)
    assert np.allclose(ctrl.gain(T, held), ctrl.gain(T, W), atol=0.2 * np.abs(optimum(T)).max())   # a refit
    riccati = weights_of(ctrl, optimum)
    assert np.array_equal(ctrl._held_where_away(riccati, 0.0), riccati)   # nothing to hold


def test_a_loop_that_overflows_is_infinite_growth_not_an_error():
    # Seen on a field-bump run: an early identified model and a gain whose rollout overflowed
    # made the 2-norm's SVD fail ("SVD did not converge") and ended the run as node_failed.
    wild = OneStepModel(100.0 * np.eye(4), model(0).gammas, np.zeros(0), np.eye(4))
    away = carries_away(wild, lambda tau: np.zeros((2, 4)), T, DT, STARTS)
    assert away.excess == 0.0                         # the model's own drift: no evidence
    stable = model(2)
    blowing = carries_away(stable, lambda tau: -1e6 * np.ones((2, 4)), T, DT, STARTS)
    assert blowing.excess > 1e100                      # rejected, whatever the tolerance
    assert worst_growth(closed_loop(wild, np.zeros((200, 2, 4))), 2, 0)[-1] == np.inf


@pytest.mark.parametrize('delay', [0, 2])
def test_a_velocity_gain_that_feeds_speed_back_beyond_the_damping_throws_a_moving_robot(delay):
    """No position gain, u = +k v: a robot at rest stays; a moving one speeds up if k > c.

    The rover's damping is c = 45 N s/m: k = 60 leaves -15 (the speed grows e^{15 t / 40}),
    k = 30 leaves +15 (it decays). From rest neither moves the robot at all.
    """
    def feeding(k):
        return lambda tau: np.hstack([np.zeros((2, 2)), -k * np.eye(2)])

    exact = model(delay, stiffness=0.0)
    thrown = carries_away(exact, feeding(60.0), T, DT, STARTS)
    assert thrown.moving and thrown.excess > 1.0
    if delay == 0:    # the speed's own recursion v_{k+1} = (e^{-cΔt/m} + k (1 - e^{-cΔt/m}) / c) v_k
        decay = math.exp(-45.0 * DT / 40.0)
        per_step = decay + 60.0 * (1.0 - decay) / 45.0
        assert math.isclose(thrown.growth, per_step ** round(T / DT), rel_tol=1e-6)
    held = carries_away(exact, feeding(30.0), T, DT, STARTS)
    assert held.excess <= 1e-9
    optimum = carries_away(exact, riccati_gain(0.0), T, DT, STARTS)
    assert optimum.excess <= 1e-9
