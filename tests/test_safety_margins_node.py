"""The safety node with a margin policy: shrinking margins, republication, violations.

The node's step is fed a scripted mission (legs along the x axis, one transient) directly,
as its lock-step gate would hand it the steps; what it publishes is checked against the
geometry: a published obstacle is the true one grown by margin + robot radius (RRT-QX
eq. 7), measured with shapely's Hausdorff distance, not with the node's own grower.
"""

import numpy as np
import pytest
import shapely
from geometry_msgs.msg import Point
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from rrtq_msgs.msg import ControllerState

from rrtq_common import conversions as conv
from rrtq_common.lockstep import Step
from rrtq_planner.safety_node import SafetyNode

BOX = [[10.0, 8.0], [14.0, 8.0], [14.0, 11.0], [10.0, 11.0]]
DT_NS = 50_000_000
STEPS_PER_LEG = 6
TRANSIENT = 2.0      # m: the first leg's deviation
CALM = 0.1           # m: every other leg's


def odom_at(stamp_ns, x, y):
    msg = Odometry()
    msg.header.stamp = conv.time_msg(stamp_ns)
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
    return msg


def leg_state(stamp_ns, index):
    state = ControllerState(leg_index=index, d0=1.0, horizon=10.0)
    state.header.stamp = conv.time_msg(stamp_ns)
    state.leg_start, state.leg_target = Point(x=float(index)), Point(x=float(index + 1))
    state.command, state.probing_noise = [0.0, 0.0], [0.0, 0.0]
    # A PD actor on the constant time function: K = [[4, 0, 3, 0], [0, 4, 0, 3]].
    state.time_rates = [0.0]
    state.actor_weights = (-np.array([[4.0, 0.0], [0.0, 4.0], [3.0, 0.0], [0.0, 3.0]])).ravel().tolist()
    return state


def mission(node, legs):
    """Drive the node over ``legs`` legs; (status, augmented publications) per step."""
    published, statuses = [], []
    node.aug_pub.publish = published.append
    node.status_pub.publish = statuses.append
    detected = conv.obstacle_array_msg(0, [('box', np.array(BOX))], 0.0)
    state, k, out = None, 0, []
    for leg in range(legs):
        deviation = TRANSIENT if leg == 0 else CALM
        for s in range(STEPS_PER_LEG):
            stamp = k * DT_NS
            y = deviation if s == STEPS_PER_LEG // 2 else 0.0
            before = len(published)
            node.step(Step(stamp, {'odom': odom_at(stamp, leg + s / STEPS_PER_LEG, y),
                                   'detected': detected, 'perception': None, 'state': state}))
            serialize_message(statuses[-1])     # what a publisher does with it (C types)
            out.append((statuses[-1], published[before:]))
            state = leg_state(stamp, leg)       # what the next step sees (lag 1)
            k += 1
    return out


def grown_by(msg):
    """m: how far the published box reaches beyond the true one (Hausdorff distance)."""
    poly = [[p.x, p.y] for p in msg.obstacles[0].polygon.points]
    return shapely.Polygon(poly).hausdorff_distance(shapely.Polygon(BOX))


@pytest.fixture
def node_of(ros):
    context, _, _ = ros
    made = []

    def make(**safety):
        # The scenario's settings, as the graph hands them (the node never reads the file).
        params = {'robot_radius': 0.5, 'bounds': [-5.0, 40.0, -10.0, 15.0], 'dt': 0.05,
                  'lockstep': True, **safety}
        node = SafetyNode(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in params.items()])
        made.append(node)
        return node
    yield make
    for node in made:
        node.destroy_node()


def test_conformal_margin_shrinks_below_the_running_max_and_is_republished(node_of):
    # δ = 0.1: 9 scores certify a quantile; a window of 10 drops the transient after 10 legs.
    steps = mission(node_of(margin='conformal', confidence=0.9, window=10,
                            initial_margin=0.3), 24)
    last, _ = steps[-1]
    assert last.margin_mode == 'conformal'
    assert last.d_rob_max == pytest.approx(TRANSIENT)
    assert last.margin == pytest.approx(CALM + 0.5)           # the window's largest calm score
    assert last.margin < last.d_rob_max + 0.5                 # below the running max's
    assert last.legs == 24 and last.samples == 10
    # The transient leg raised the margin at once (a violation of the 0.3 m in force) ...
    assert last.violations == 1
    assert sum(s.violations > 0 and not p.violations for (s, _), (p, _)
               in zip(steps[1:], steps[:-1])) == 1
    # ... and every publication carries the margin in force, grown and shrunk alike.
    margins = [(status.margin, msgs[0]) for status, msgs in steps if msgs]
    for margin, msg in margins:
        assert grown_by(msg) == pytest.approx(margin, rel=0.006)
    values = [m for m, _ in margins]
    assert max(values) == pytest.approx(TRANSIENT + 0.5)
    assert values[-1] == pytest.approx(CALM + 0.5)             # republished when it shrank
    assert any(b < a for a, b in zip(values, values[1:]))


def test_running_max_never_shrinks_and_counts_no_violations(node_of):
    steps = mission(node_of(), 24)
    last, _ = steps[-1]
    assert last.margin_mode == 'running_max' and last.violations == 0
    assert last.margin == pytest.approx(TRANSIENT + 0.5)
    values = [status.margin for status, msgs in steps if msgs]
    assert values == sorted(values)


def test_learned_bound_runs_in_the_node_and_starts_from_its_initial_margin(node_of):
    # Before any fit the bank has no finite level: the margin is initial_margin (0.3 m),
    # raised to the leg's own deviation once that exceeds it (the transient leg).
    steps = mission(node_of(margin='learned_bound', initial_margin=0.3), 3)
    first, _ = steps[1]
    assert first.margin_mode == 'learned_bound' and first.leg_margin == pytest.approx(0.3)
    transient, _ = steps[STEPS_PER_LEG - 1]
    assert transient.margin == pytest.approx(TRANSIENT + 0.5) and transient.violations == 1
    assert all(np.isfinite(s.margin) for s, _ in steps)


def test_the_gain_rebuilt_from_the_state_is_the_controllers():
    from rrtq_controller.config import ControllerConfig
    from rrtq_controller.q_learning import QLearningController
    from rrtq_common.actor import actor_gain
    ctrl = QLearningController(ControllerConfig(time_powers=(1, 2)), 4, 2, 0,
                               np.random.default_rng(0))
    ctrl._Wa = np.random.default_rng(1).normal(size=ctrl._Wa.shape)
    basis = ctrl.time_basis
    gain = actor_gain(ctrl.actor_weights, basis.rates, basis.powers, basis.horizon, 4, 2)
    for tau in (10.0, 6.3, 0.7, 0.0, -1.0):
        np.testing.assert_allclose(gain(tau), ctrl.gain(tau), rtol=1e-12, atol=1e-12)
    assert actor_gain([], basis.rates, basis.powers, basis.horizon, 4, 2) is None


def test_the_status_reports_the_obstacle_ahead_along_the_velocity(node_of):
    """Below the box, heading up at it: /safety/status carries the distance the robot's
    disc (radius 0.5 m) travels before it meets the box's bottom face (y = 8) and that
    face's normal toward the robot; heading away, none. The nearest obstacle is the same
    box here, so both are reported on one geometry."""
    node = node_of()
    statuses = []
    node.status_pub.publish = statuses.append
    detected = conv.obstacle_array_msg(0, [('box', np.array(BOX))], 0.0)
    for k, vy in enumerate((1.0, -1.0, 0.0)):
        odom = odom_at(k * DT_NS, 12.0, 4.0)
        odom.twist.twist.linear.y = vy
        node.step(Step(k * DT_NS, {'odom': odom, 'detected': detected, 'perception': None,
                                   'state': None}))
        serialize_message(statuses[-1])
    toward, away, still = statuses
    assert toward.ahead_distance == pytest.approx(8.0 - 0.5 - 4.0)
    assert (toward.ahead_direction.x, toward.ahead_direction.y) == pytest.approx((0.0, -1.0))
    assert toward.obstacle_distance == pytest.approx(8.0 - 4.0 - 0.5)
    assert away.ahead_distance == float('inf') and still.ahead_distance == float('inf')
