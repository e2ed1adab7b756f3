"""Perception: a scripted drive past obstacles that appear, vanish and are believed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_common.world import ObstacleSpec, TrueObstacles
from rrtq_sim.perception import ObstacleEvent, Perception

DET, REM = ObstacleEvent.DETECTED, ObstacleEvent.REMOVED


def box(x0, x1, y0, y1):
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


WORLD = [
    ObstacleSpec('A', box(4.0, 5.0, 1.0, 2.0)),  # static, unknown
    ObstacleSpec('B', box(7.5, 8.5, -1.5, -0.5), vanish_at=0.0, known=True),  # believed, never there
    ObstacleSpec('C', box(5.5, 6.5, -1.5, -1.0), appear_at=8.0),  # appears after the robot passed
    ObstacleSpec('D', box(9.2, 9.8, 0.5, 1.0), known=True),  # known and real: never an event
    ObstacleSpec('E', box(20.0, 21.0, 20.0, 21.0), vanish_at=2.0),  # never within range
    ObstacleSpec('G', box(6.5, 7.0, 1.2, 1.8), vanish_at=4.0, known=True),  # known, then gone
    ObstacleSpec('H', box(0.5, 1.0, 1.0, 1.5), vanish_at=1.5),  # seen, then vanishes
]


def test_scripted_drive_events_step_by_step():
    perception = Perception(WORLD, radius=2.0)
    assert perception.known_ids == frozenset({'B', 'D', 'G'})
    got = {k: perception.step(np.array([float(k), 0.0]), float(k)) for k in range(11)}
    expected = {k: [] for k in range(11)}
    expected |= {0: [(DET, 'H')], 2: [(REM, 'H')], 3: [(DET, 'A')], 5: [(REM, 'G')], 6: [(REM, 'B')], 8: [(DET, 'C')]}
    assert got == expected
    assert perception.known_ids == frozenset({'A', 'C', 'D'})
    assert [s.id for s in perception.known_obstacles()] == ['A', 'C', 'D']


def test_detection_is_reported_once():
    perception = Perception([ObstacleSpec('A', box(0.0, 1.0, 0.0, 1.0))], radius=1.0)
    assert perception.step([1.5, 0.5], 0.0) == [(DET, 'A')]
    assert perception.step([1.5, 0.5], 0.1) == []
    assert perception.step([0.5, 0.5], 0.2) == []


def test_same_step_events_follow_scenario_order():
    far_first = [ObstacleSpec('far', box(1.5, 2.0, 0.0, 1.0)), ObstacleSpec('near', box(0.2, 0.4, 0.0, 1.0))]
    events = Perception(far_first, radius=2.0).step([0.0, 0.0], 0.0)
    assert events == [(DET, 'far'), (DET, 'near')]


def test_disc_not_bounding_box_decides():
    # A thin diagonal sliver: its bounding box reaches the sensing disc, the sliver does not.
    sliver = np.array([[2.0, 0.0], [0.0, 2.0], [0.1, 2.0], [2.0, 0.1]]) + 1.0
    perception = Perception([ObstacleSpec('s', sliver)], radius=1.2)
    assert perception.step([0.5, 0.5], 0.0) == []
    assert perception.step([0.5 + 2.0 / math.sqrt(2.0) - 0.6, 0.5 + 2.0 / math.sqrt(2.0) - 0.6], 0.0) == [(DET, 's')]


def test_exists_window_is_half_open():
    truth = TrueObstacles([ObstacleSpec('x', box(0, 1, 0, 1), appear_at=2.0, vanish_at=5.0)], 0.5, 1.0)
    far = [10.0, 10.0]
    assert [len(truth.update(far, t)) for t in (1.9, 2.0, 4.9, 5.0)] == [0, 1, 1, 0]


def test_before_any_update_the_truth_is_that_of_t0():
    truth = TrueObstacles(WORLD, robot_radius=0.5, clearance=1.0)
    assert [s.id for s in truth.existing] == ['A', 'D', 'E', 'G', 'H']


def _drive(truth, path):
    """Feed (t, x) samples with y = 0; the ids existing after each."""
    return [[s.id for s in truth.update([x, 0.0], t)] for t, x in path]


def test_an_appearing_obstacle_is_held_back_while_the_robot_is_near():
    # Due at t = 1 over the robot's path; the robot (radius 0.5, clearance 1) is within
    # 1.5 m of it until it has passed x = 4.5: it appears at the first step after that.
    due = ObstacleSpec('due', box(2.0, 3.0, -0.5, 0.5), appear_at=1.0)
    truth = TrueObstacles([due], robot_radius=0.5, clearance=1.0)
    path = [(0.5 * k, 0.5 * k) for k in range(13)]            # x = t, from 0 to 6
    existing = _drive(truth, path)
    first = next(k for k, ids in enumerate(existing) if ids)
    assert path[first][1] > 4.5 >= path[first - 1][1]
    assert all(ids == ['due'] for ids in existing[first:])
    assert truth.appeared_at == {'due': path[first][0]} and truth.held == frozenset()


def test_held_back_obstacles_are_reported_and_not_perceived():
    due = ObstacleSpec('due', box(2.0, 3.0, -0.5, 0.5), appear_at=1.0)
    perception = Perception([due], radius=5.0, truth=TrueObstacles([due], 0.5, 1.0))
    assert perception.step([1.0, 0.0], 1.0) == []
    assert perception.truth.held == frozenset({'due'})
    assert perception.step([4.6, 0.0], 2.0) == [(DET, 'due')]
    assert perception.truth.held == frozenset()


def test_an_obstacle_held_past_its_vanish_time_never_exists():
    brief = ObstacleSpec('brief', box(0.0, 1.0, -0.5, 0.5), appear_at=1.0, vanish_at=2.0)
    truth = TrueObstacles([brief], robot_radius=0.2, clearance=0.0)
    assert _drive(truth, [(t, 0.5) for t in (1.0, 1.5)] + [(t, 5.0) for t in (2.0, 3.0)]) == [[]] * 4
    assert truth.appeared_at == {}


def test_obstacles_of_t0_are_never_held_and_zero_clearance_still_spares_the_robot():
    there = ObstacleSpec('there', box(0.6, 1.0, -0.5, 0.5))     # 0.1 m from the robot's disc
    late = ObstacleSpec('late', box(-1.0, 1.0, -1.0, 1.0), appear_at=0.5)  # would cover it
    truth = TrueObstacles([there, late], robot_radius=0.5, clearance=0.0)
    assert _drive(truth, [(0.0, 0.0), (0.5, 0.0), (1.0, 0.0)]) == [['there']] * 3
    assert truth.held == frozenset({'late'})
    assert _drive(truth, [(1.5, 3.0)]) == [['there', 'late']]


def test_bad_inputs():
    with pytest.raises(ValueError):
        Perception(WORLD, radius=0.0)
    with pytest.raises(ValueError):
        Perception([ObstacleSpec('a', box(0, 1, 0, 1)), ObstacleSpec('a', box(2, 3, 0, 1))], radius=1.0)
    with pytest.raises(ValueError):
        Perception(WORLD, radius=1.0).step([0.0, 0.0, 0.0], 0.0)
    with pytest.raises(ValueError):
        TrueObstacles(WORLD, robot_radius=-0.1)
    with pytest.raises(ValueError):
        TrueObstacles(WORLD, clearance=math.nan)
    assert Perception([], radius=1.0).step([0.0, 0.0], 0.0) == []
