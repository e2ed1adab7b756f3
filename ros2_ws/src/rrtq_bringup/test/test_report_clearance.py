"""The report's referee: clearance from /odom against the recorded truth, signed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rrtq_bringup.report.run import summarise, true_clearance
from rrtq_bringup.run_data import RunData

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])


def run_data(odom_t, positions, truth) -> RunData:
    empty = np.zeros(0)
    fields = {f.name: empty for f in dataclasses.fields(RunData)
              if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING}
    fields.update(
        odom_t=np.asarray(odom_t, dtype=float),
        odom_x=np.column_stack([positions, np.zeros((len(positions), 2))]),
        cmd_u=np.zeros((0, 2)), leg_target=np.zeros((0, 2)), leg_index=np.zeros(0, dtype=int),
        critic_w=[], actor_w=[], disturbance_w=[], truth=truth, detected=[], augmented=[],
        plans=[], tree_segments=None, goal=np.array([10.0, 10.0]), topics={})
    return RunData(**fields)


def test_clearance_is_signed_and_follows_the_truth_over_time():
    # The square exists from t = 1 s to t = 3 s; the robot sits inside it throughout.
    late = SQUARE + [5.0, 0.0]
    truth = [(0.0, [('far', late)]), (1.0, [('far', late), ('sq', SQUARE)]), (3.0, [])]
    data = run_data([0.0, 1.0, 2.0, 3.0], np.array([[1.0, 0.5]] * 4), truth)
    np.testing.assert_allclose(true_clearance(data, 0.0), [4.0, -0.5, -0.5, np.inf])
    np.testing.assert_allclose(true_clearance(data, 0.25), [3.75, -0.75, -0.75, np.inf])


def test_a_point_robot_inside_a_true_obstacle_is_a_collision():
    data = run_data([0.0, 0.05], np.array([[-1.0, 1.0], [1.0, 1.0]]), [(0.0, [('sq', SQUARE)])])
    summary = summarise(data, {'robot_radius': 0.0})
    assert summary['collided'] is True
    assert summary['min_clearance_m'] == pytest.approx(-1.0)
