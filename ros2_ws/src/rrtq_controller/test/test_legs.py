"""Leg sequencing with D0, D and the window D <= rho D0 (RRT-QX (4)-(5))."""

import numpy as np

from rrtq_controller.legs import LegEvent, LegSequencer


def test_window_switches_to_the_next_waypoint_and_keeps_velocity():
    seq = LegSequencer(rho=0.15, horizon=10.0)
    leg = seq.set_plan([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]], np.zeros(4), 0.0)
    assert leg is not None and np.allclose(leg.target, [4, 0, 0, 0])  # start waypoint skipped
    assert np.isclose(leg.d0, 4.0)
    assert seq.update(np.array([3.0, 0.0, 0.5, 0.0]), 1.0) is LegEvent.CONTINUE  # D = 1.118 > 0.6
    assert seq.update(np.array([3.5, 0.0, 0.3, 0.0]), 2.0) is LegEvent.NEW_LEG  # D = 0.58 <= 0.6
    assert seq.leg is not None and seq.leg.index == 1
    assert np.allclose(seq.x_bar([3.5, 0.0, 0.3, 0.0]), [-0.5, -3.0, 0.3, 0.0])
    assert np.isclose(seq.leg.d0, np.linalg.norm([-0.5, -3.0, 0.3, 0.0]))


def test_goal_and_horizon_restart_and_new_plan():
    seq = LegSequencer(rho=0.1, horizon=10.0)
    seq.set_plan([[1.0, 0.0]], np.array([0.0, 0.0, 0.0, 0.0]), 0.0)
    assert seq.update(np.array([0.5, 0.0, 0.0, 0.0]), 10.0) is LegEvent.NEW_LEG  # T elapsed
    assert seq.leg is not None and np.isclose(seq.leg.d0, 0.5)
    assert seq.update(np.array([0.96, 0.0, 0.0, 0.0]), 11.0) is LegEvent.GOAL_REACHED
    # station keeping through the leg's horizon (started at 10 s): the same target, a fresh horizon
    assert seq.update(np.array([0.96, 0.0, 0.0, 0.0]), 20.0) is LegEvent.RENEWED
    assert seq.leg.index == 2 and seq.leg.start_time == 20.0 and np.isclose(seq.leg.d0, 0.04)
    assert seq.update(np.array([0.96, 0.0, 0.0, 0.0]), 29.0) is LegEvent.CONTINUE
    assert seq.update(np.array([0.96, 0.0, 0.0, 0.0]), 30.0) is LegEvent.RENEWED
    leg = seq.set_plan([[5.0, 5.0]], np.array([0.96, 0.0, 0.1, 0.0]), 31.0)
    assert leg is not None and leg.index == 4 and not seq.goal_reached
