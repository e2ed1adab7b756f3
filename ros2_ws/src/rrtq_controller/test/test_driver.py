"""The driver: plans become legs, a repaired plan through the same target keeps the leg."""

import numpy as np
from scipy.linalg import expm

from rrtq_controller.config import ControllerConfig
from rrtq_controller.driver import LearningDriver
from rrtq_controller.legs import LegSequencer

MASS, DAMPING = 40.0, 45.0
A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [0, 0, -DAMPING / MASS, 0], [0, 0, 0, -DAMPING / MASS]])
B = np.array([[0, 0], [0, 0], [1 / MASS, 0], [0, 1 / MASS]])


PD = ((40, 0, 30, 0), (0, 40, 0, 30))   # an admissible first policy for the 40 kg rover


def zoh(dt):
    big = np.zeros((6, 6))
    big[:4, :4], big[:4, 4:] = A, B
    e = expm(big * dt)
    return e[:4, :4], e[:4, 4:]


def test_follow_plan_keeps_the_leg_when_the_target_stays():
    legs = LegSequencer(rho=0.15, horizon=10.0)
    x = np.zeros(4)
    assert legs.follow_plan([[0, 0], [5, 0], [5, 5]], x, 0.0)      # first plan: new leg
    assert legs.leg.index == 0 and np.allclose(legs.leg.target[:2], [5, 0])
    # The planner repaired what lies beyond the target: the leg goes on.
    assert not legs.follow_plan([[5, 0], [7, 3], [5, 5]], x, 1.0)
    assert legs.leg.index == 0
    # A plan that no longer passes through the target starts a new leg.
    assert legs.follow_plan([[0, 2], [5, 5]], x, 2.0)
    assert legs.leg.index == 1 and np.allclose(legs.leg.target[:2], [0, 2])


def test_a_plan_that_reaches_the_target_another_way_starts_a_new_leg():
    """The leg's target reappearing later in a plan is not the same route: the waypoints
    before it lie ahead of the robot, and the straight way to the target is not what the
    planner checked (a robot sent straight at its goal cut a wall's corner). A waypoint the
    robot has already passed (the planner lagging) does not break the leg."""
    legs = LegSequencer(rho=0.15, horizon=10.0)
    x = np.array([-8.0, -1.5, 0.0, 0.0])
    assert legs.follow_plan([[15.0, -1.0]], x, 0.0)                  # straight at the goal
    assert legs.follow_plan([[4.7, 0.0], [8.8, -0.7], [15.0, -1.0]], x, 0.1)
    assert legs.leg.index == 1 and np.allclose(legs.leg.target[:2], [4.7, 0.0])
    # The robot reaches its window and moves on to the next waypoint by itself; the
    # planner, lagging, still names the one it has passed: the leg goes on.
    x = np.array([4.6, 0.0, 1.0, 0.0])
    legs.update(x, 0.2)
    assert legs.leg.index == 2 and np.allclose(legs.leg.target[:2], [8.8, -0.7])
    x = np.array([5.5, -0.1, 1.0, 0.0])
    assert not legs.follow_plan([[4.7, 0.0], [8.8, -0.7], [15.0, -1.0]], x, 0.3)
    assert legs.leg.index == 2


def test_driver_walks_the_waypoints_to_the_goal():
    dt = 0.05
    phi, gam = zoh(dt)
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, initial_gain=PD,
                              probing_std=5.0)
    driver = LearningDriver(config, 4, 2, 1, np.random.default_rng(1))
    x = np.zeros(4)
    driver.set_plan([[0, 0], [4, 0], [4, 4]], x, 0.0)
    targets = set()
    for k in range(int(40 / dt)):
        out = driver.step(k * dt, x)
        targets.add(tuple(np.round(out.leg_target, 6)))
        x = phi @ x + gam @ out.u
    assert targets == {(4.0, 0.0), (4.0, 4.0)}
    assert np.linalg.norm(x[:2] - [4, 4]) < 0.3
    assert out.leg_index >= 1 and out.critic_weights.size > 0


def test_an_empty_plan_holds_the_robot_where_it_is():
    dt = 0.05
    phi, gam = zoh(dt)
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, initial_gain=PD,
                              probing_std=0.0)
    driver = LearningDriver(config, 4, 2, 1, np.random.default_rng(1))
    x = np.array([1.0, 2.0, 0.8, -0.5])              # moving when the path is lost
    driver.set_plan([], x, 0.0)
    for k in range(int(10 / dt)):
        out = driver.step(k * dt, x)
        x = phi @ x + gam @ out.u
    assert np.allclose(out.leg_target, [1.0, 2.0])
    assert np.linalg.norm(x[2:]) < 0.05 and np.linalg.norm(x[:2] - [1.0, 2.0]) < 0.3


def test_keeping_station_past_the_horizon_renews_it_and_holds_the_position():
    """Seen in the defaults-only bench: the robot held where it was (no path) for 18 s, and
    past the horizon the controller used K̂(τ = 0), which holds no position (the optimum's
    K(0) = R⁻¹BᵀP(T) acts on velocity only) and was unidentified: it drove the robot 16 m
    into an obstacle. Station keeping renews the horizon instead: τ never stays at 0, and a
    push long after the horizon is taken back."""
    dt = 0.05
    phi, gam = zoh(dt)
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, initial_gain=PD, probing_std=0.0)
    driver = LearningDriver(config, 4, 2, 1, np.random.default_rng(1))
    x = np.array([1.0, 2.0, 0.0, 0.0])
    driver.set_plan([], x, 0.0)
    taus, events = [], set()
    for k in range(int(45 / dt)):
        if k == int(30 / dt):
            x = x + np.array([0.0, 0.0, 1.0, -0.5])          # a push, 30 s into the hold
        out = driver.step(k * dt, x)
        taus.append(out.time_to_go)
        events.add(out.event)
        x = phi @ x + gam @ out.u
    assert 'renewed' in events
    assert min(taus[int(10.5 / dt):]) > 0.0
    assert np.linalg.norm(x[:2] - [1.0, 2.0]) < 0.1 and np.linalg.norm(x[2:]) < 0.05
