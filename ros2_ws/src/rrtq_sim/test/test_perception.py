"""Perception: a scripted drive past obstacles that appear, vanish and are believed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_sim.perception import ObstacleEvent, Perception
from rrtq_sim.scenario import ObstacleSpec

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
    spec = ObstacleSpec('x', box(0, 1, 0, 1), appear_at=2.0, vanish_at=5.0)
    assert [Perception.exists(spec, t) for t in (1.9, 2.0, 4.9, 5.0)] == [False, True, True, False]


def test_bad_inputs():
    with pytest.raises(ValueError):
        Perception(WORLD, radius=0.0)
    with pytest.raises(ValueError):
        Perception([ObstacleSpec('a', box(0, 1, 0, 1)), ObstacleSpec('a', box(2, 3, 0, 1))], radius=1.0)
    with pytest.raises(ValueError):
        Perception(WORLD, radius=1.0).step([0.0, 0.0, 0.0], 0.0)
    assert Perception([], radius=1.0).step([0.0, 0.0], 0.0) == []
