"""The referee: collisions and clearance against the true obstacles, over time."""

from __future__ import annotations

import numpy as np
import pytest

from rrtq_bringup.mission import MissionConfig, MissionMonitor, Outcome
from rrtq_common.geometry import point_polygon_distance, polygon_from_circle
from rrtq_common.world import ObstacleSpec, TrueObstacles

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])


def monitor(specs, robot_radius=0.0):
    config = MissionConfig(goal=(50.0, 50.0), goal_tolerance=0.5, duration=100.0,
                           robot_radius=robot_radius, bounds=((-100.0, 100.0), (-100.0, 100.0)),
                           dt=0.05)
    return MissionMonitor(config, TrueObstacles(specs, robot_radius))


def test_a_point_robot_inside_an_obstacle_has_collided():
    referee = monitor([ObstacleSpec('box', SQUARE)])
    assert referee.on_odometry(0.0, np.array([-1.0, 1.0])) is Outcome.RUNNING
    assert referee.on_odometry(0.05, np.array([1.0, 1.2])) is Outcome.COLLISION
    assert referee.collided and referee.min_clearance == pytest.approx(-0.8)


def test_clearance_is_the_nearest_existing_obstacle_of_a_forest():
    rng = np.random.default_rng(4)
    specs = [ObstacleSpec(f't{i}', polygon_from_circle(rng.uniform(0, 40, 2), 0.8),
                          appear_at=float(rng.choice([0.0, 5.0])),
                          vanish_at=float(rng.choice([np.inf, 8.0])))
             for i in range(200)]
    referee = monitor(specs, robot_radius=0.3)
    for t, position in zip(np.arange(0.0, 12.0, 0.5), rng.uniform(0, 40, (24, 2))):
        alive = [s for s in specs if s.exists(t)]
        want = min(float(point_polygon_distance(position, s.polygon)) for s in alive) - 0.3
        inside = any(float(point_polygon_distance(position, s.polygon)) == 0.0 for s in alive)
        got = referee.clearance(position, t)
        assert got < -0.3 if inside else got == pytest.approx(want, abs=1e-9)


def test_leaving_the_bounds_ends_the_run_out_of_bounds_with_time_and_position():
    config = MissionConfig(goal=(4.0, 0.0), goal_tolerance=0.5, duration=100.0,
                           robot_radius=0.3, bounds=((-5.0, 5.0), (-2.0, 2.0)), dt=0.05)
    referee = MissionMonitor(config, TrueObstacles([]))
    # Along the lower edge, then out through it: the robot's centre judges, not its disc.
    assert referee.on_odometry(0.0, np.array([-3.0, -1.9])) is Outcome.RUNNING
    assert referee.on_odometry(0.05, np.array([-3.0, -2.0])) is Outcome.RUNNING
    assert referee.on_odometry(0.10, np.array([-3.0, -2.25])) is Outcome.OUT_OF_BOUNDS
    assert 't=0.10 s' in referee.reason and '(-3.00, -2.25)' in referee.reason
    assert '0.250 m outside' in referee.reason
    # Over: a later sample, even at the goal, changes nothing.
    assert referee.on_odometry(0.15, np.array([4.0, 0.0])) is Outcome.OUT_OF_BOUNDS
    summary = referee.summary()
    assert summary['outcome'] == 'out_of_bounds' and summary['success'] is False
    assert summary['collided'] is False and summary['steps'] == 3
