"""The divergence watch of safe learning: D, the speed, the line, restarted legs, noise.

Ground truth from the true plants (rrtq_testing.controller_reference), which the
controller never sees.
"""

import numpy as np

import pytest
from scipy.stats import norm

from rrtq_controller.guard import FALSE_ALARM, DivergenceWatch

T = 10.0


def test_divergence_watch_keeps_its_reference_across_restarted_legs():
    """A robot running away while new plans restart its legs (each from farther away) is
    still caught: legs that did not begin afresh keep the reference start."""
    watch = DivergenceWatch(distance=3.0, floor=1.0, speed=6.0, horizon=10.0)
    watch.start(np.array([-3.0, 0.0, 0.0, 0.0]))
    assert watch.check(np.array([-5.0, 0.0, 0.5, 0.0])) == ''
    watch.start(np.array([-8.0, 0.0, 1.0, 0.0]), renew=False)
    assert 'D =' in watch.check(np.array([-10.5, 0.0, 1.0, 0.0]))
    watch.start(np.array([-8.0, 0.0, 1.0, 0.0]), renew=True)
    assert watch.check(np.array([-10.5, 0.0, 1.0, 0.0])) == ''
    assert 'speed' in watch.check(np.array([-10.5, 0.0, 20.0, 0.0]))


def test_a_leg_that_started_on_its_target_is_no_reference():
    """At rest before the first plan (D0 = 0) the plan's first leg becomes the reference."""
    watch = DivergenceWatch(distance=3.0, floor=1.0, speed=6.0, horizon=10.0)
    watch.start(np.zeros(4))
    watch.start(np.array([-3.2, -0.7, 0.0, 0.0]), renew=False)
    assert watch.check(np.array([-3.2, -0.7, 0.1, 0.0])) == ''
    assert 'D =' in watch.check(np.array([-12.0, 0.0, 0.1, 0.0]))


def test_a_new_plan_to_a_farther_waypoint_is_not_a_robot_running_away():
    """Seen in the defaults-only bench: 1.1 m from its target, the robot gets a new plan
    whose first waypoint is 4.4 m away (the route changed around an obstacle); measured
    from the new target that is D > 3 D0 + 1 = 4.3 and the watch tripped. Told how far
    the target moved, it measures from the reference leg's target: no trip while the
    robot stays put, and a trip still when it then runs away from where it was sent."""
    watch = DivergenceWatch(distance=3.0, floor=1.0, speed=6.0, horizon=10.0)
    watch.start(np.array([-1.1, 0.0, 0.0, 0.0]))               # target at (1.1, 0), robot at 0
    moved = np.array([-3.7, 3.6, 0.0, 0.0])                    # the new waypoint: (-2.6, 3.6)
    x_new = np.array([2.6, -3.6, 0.0, 0.0])                    # the robot, seen from it
    assert np.linalg.norm(x_new) > 3.0 * 1.1 + 1.0
    watch.start(x_new, renew=False, moved=moved)
    assert watch.check(x_new) == ''
    assert 'D =' in watch.check(x_new + np.array([-4.5, 0.0, 0.3, 0.0]))    # 5.6 m from (1.1, 0)
    unknown = DivergenceWatch(distance=3.0, floor=1.0, speed=6.0, horizon=10.0)
    unknown.start(np.array([-1.1, 0.0, 0.0, 0.0]))
    unknown.start(x_new, renew=False)                          # not told: the old rule
    assert 'D =' in unknown.check(x_new)


def test_a_robot_that_follows_replanned_waypoints_is_not_running_away():
    """Seen on a 120 kg rover: new plans kept replacing the robot's waypoint before it
    reached it (no leg completed), and measured from the target three replans back the
    robot was D = 7.5 m away, past 2 D0 + 1 = 7.45, on a leg whose own D had fallen from
    4.4 to 1.7 m: the watch held and the policy was thrown away. A leg that ends nearer
    its target than it started made progress and the next leg is the reference; a robot
    that gets farther from its target is still measured from the old one."""
    watch = DivergenceWatch(distance=2.0, floor=1.0, speed=4.0, horizon=10.0)
    target = np.array([3.0, 0.0])
    robot = np.zeros(2)
    watch.start(np.array([*(robot - target), 0.0, 0.0]))
    for _ in range(6):                                   # 2 m of each 3 m leg, then a replan
        robot = robot + 2.0 * (target - robot) / np.linalg.norm(target - robot)
        x = np.array([*(robot - target), 0.5, 0.0])
        assert watch.check(x) == ''
        new_target = target + np.array([2.0, 2.0])
        watch.start(np.array([*(robot - new_target), 0.5, 0.0]), renew=False,
                    moved=np.array([*(new_target - target), 0.0, 0.0]))
        target = new_target
    assert np.linalg.norm(robot) > 3.0 * (2.0 * 3.0 + 1.0) / 2.0  # far past the first reference
    assert watch.check(np.array([*(robot - target), 0.5, 0.0])) == ''
    # a leg that ended farther from its target than it started: the reference stays
    away = DivergenceWatch(distance=2.0, floor=1.0, speed=4.0, horizon=10.0)
    away.start(np.array([-3.0, 0.0, 0.0, 0.0]))          # target 3 m ahead
    x_end = np.array([-4.5, 0.0, -0.5, 0.0])             # 1.5 m backwards
    moved = np.array([0.0, 2.0, 0.0, 0.0])
    away.start(x_end - moved, renew=False, moved=moved)
    assert 'D =' in away.check(x_end - moved + np.array([-3.0, 0.0, -0.5, 0.0]))


def test_the_watch_trips_when_the_robot_leaves_its_line_beyond_the_widest_before():
    """The distance from the leg's segment past the running max of D_rob (the distance
    from the line) of the legs before plus ``deviation``: the margin the plan's obstacles
    were grown by no longer holds."""
    watch = DivergenceWatch(distance=3.0, floor=1.0, speed=6.0, horizon=10.0, deviation=0.25)
    watch.start(np.array([-4.0, 0.0, 0.0, 0.0]))         # along x; the line is y = 0
    assert watch.check(np.array([-3.0, 0.2, 0.3, 0.1])) == ''   # 0.2 m off: within 0 + 0.25
    assert watch.widest == pytest.approx(0.2)
    reason = watch.check(np.array([-2.5, 0.3, 0.3, 0.1]))
    assert watch.off_line and 'off its line' in reason
    assert watch.widest == pytest.approx(0.3)
    # the next leg may go as far as the widest so far plus the allowance, not further
    watch.start(np.array([0.0, -4.0, 0.0, 0.0]))         # along y; the line is x = 0
    assert watch.check(np.array([0.5, -2.0, 0.0, 0.3])) == '' and not watch.off_line
    assert watch.check(np.array([0.56, -1.0, 0.0, 0.3])) != '' and watch.off_line


def test_a_leg_too_short_for_a_line_is_watched_as_its_segment():
    """Holding station (a leg no longer than ``deviation``): the robot may go as far from
    the leg's segment as the widest D_rob before plus ``deviation``, plus the way its
    speed at the leg's start covers in ``stop_time``; past the target as well as behind
    the start. Before, such a leg was not watched for it: an unstable policy drove an
    80 kg rover 2.3 m from its hold point before D tripped."""
    watch = DivergenceWatch(distance=2.0, floor=1.0, speed=4.0, horizon=10.0, deviation=0.25,
                            stop_time=1.0)
    watch.widest = 0.3
    watch.start(np.array([0.1, 0.0, 0.0, 0.0]))          # at rest, 0.1 m from its target
    assert watch.check(np.array([-0.4, 0.0, 0.0, 0.0])) == ''   # 0.5 m past the target
    reason = watch.check(np.array([-0.6, 0.1, 0.0, 0.0]))       # 0.61 m: D = 0.61 < 2 D0 + 1
    assert watch.off_line and 'short leg' in reason
    watch = DivergenceWatch(distance=2.0, floor=1.0, speed=4.0, horizon=10.0, deviation=0.25,
                            stop_time=1.0)
    watch.widest = 0.3
    watch.start(np.array([0.1, 0.0, -0.8, 0.0]))         # told to hold while moving at 0.8 m/s
    assert watch.check(np.array([-1.2, 0.0, -0.3, 0.0])) == ''   # 1.2 m on: within 1.35
    assert watch.check(np.array([-1.4, 0.0, -0.2, 0.0])) != '' and watch.off_line


def test_the_watch_sees_a_robot_drifting_backwards_along_its_line_past_the_start():
    """D_rob is blind along the line; the ray is not. A robot 0.6 m behind its start, on
    the line, has D_rob = 0 but is 0.6 m outside the region the plan kept clear. Past the
    target the ray is the line: an overshoot is measured as D_rob."""
    watch = DivergenceWatch(distance=3.0, floor=1.0, speed=6.0, horizon=10.0, deviation=0.25)
    watch.start(np.array([-1.0, 0.0, 0.0, 0.0]))         # from (-1, 0) to the origin
    assert watch.check(np.array([-1.2, 0.0, -0.1, 0.0])) == ''  # 0.2 m behind the start
    reason = watch.check(np.array([-1.6, 0.0, -0.1, 0.0]))       # 0.6 m behind: D_rob = 0
    assert watch.off_line and 'off its line (ray)' in reason and watch.widest == 0.0
    watch.start(np.array([-1.0, 0.0, 0.0, 0.0]))
    assert watch.check(np.array([0.9, 0.2, 0.1, 0.0])) == ''    # 0.9 m past the target
    assert watch.check(np.array([0.9, 0.3, 0.1, 0.0])) != '' and watch.off_line


def test_the_line_watch_allows_for_the_position_noise_at_its_false_alarm_rate():
    """The limit off the line grows by z σ_p, z the two-sided quantile of α = 1 % per leg
    (T / Δt steps). With no tolerance beyond the margin (``deviation`` 0), a robot exactly on
    its line, seen through odometry of σ_p, trips the watch on nearly every leg without the
    allowance, and with it on at most α of them."""
    x0 = np.array([-5.0, 0.0, 0.0, 0.0])
    exact = DivergenceWatch(2.0, 1.0, 4.0, T, deviation=0.0, steps=200)
    noisy = DivergenceWatch(2.0, 1.0, 4.0, T, deviation=0.0, steps=200, position_std=0.02)
    exact.start(x0)
    noisy.start(x0)
    z = norm.ppf(1.0 - FALSE_ALARM / 400)
    assert noisy.line_limit - exact.line_limit == pytest.approx(z * 0.02)
    rng = np.random.default_rng(0)
    legs = 500
    tripped = {'exact': 0, 'noisy': 0}
    for name, watch in (('exact', exact), ('noisy', noisy)):
        for _ in range(legs):
            watch.widest = 0.0            # the margin: no leg before
            watch.start(x0)
            for k in range(200):          # on the line, toward the target: only the noise
                x = np.array([-5.0 + 0.02 * k, 0.0, 0.4, 0.0])
                x[:2] += rng.normal(0.0, 0.02, 2)
                if watch.check(x):
                    tripped[name] += 1
                    break
    assert tripped['exact'] > 0.9 * legs
    assert tripped['noisy'] / legs <= FALSE_ALARM + 5 * np.sqrt(FALSE_ALARM / legs)
