"""The planner node's guidance publisher (planner.guidance.mode: gvf) on an in-process executor.

Driven by the test as the graph drives it in lock-step: the goal, an augmented set, then
odometry and the safety status naming that set, step by step. Each step is answered by
a /guidance/reference stamped with it (before the statistics), sampled every dt from the
robot's position, naming the obstacle set it was built on; once the planner has a path
the reference runs round the obstacle (outside its repulsive boundary) toward the goal.
In waypoints mode (the default) the node publishes no reference at all.
"""

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rrtq_msgs.msg import GuidanceReference, ObstacleArray, PlannerStats, SafetyStatus

from rrtq_bringup.testing import Collector, spin_until
from rrtq_common import conversions as conv
from rrtq_common import qos
from rrtq_common.geometry import polygon_from_circle
from rrtq_common.polygon_set import PolygonSet

DT_NS = 50_000_000
DISC = polygon_from_circle((0.0, 0.0), 1.5, 24)


def planner(context, **extra):
    from rrtq_planner.planner_node import PlannerNode
    overrides = dict(lockstep=True, dt=0.05, bounds=[-10.0, 10.0, -10.0, 10.0],
                     steer_distance=3.0, iterations_per_step=100, **extra)
    return PlannerNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])


def drive(context, executor, node, steps):
    """Goal (6, 5), the disc at stamp 0, then ``steps`` lock-step steps from (-6, -6)."""
    driver = __import__('rclpy').create_node('driver', context=context)
    executor.add_node(node)
    executor.add_node(driver)
    refs = Collector(driver, GuidanceReference, '/guidance/reference', qos.STREAM)
    stats = Collector(driver, PlannerStats, '/planner/stats', qos.STREAM)
    goal = PoseStamped()
    goal.pose.position.x, goal.pose.position.y = 6.0, 5.0
    driver.create_publisher(PoseStamped, '/goal_pose', qos.LATCHED).publish(goal)
    driver.create_publisher(ObstacleArray, '/obstacles/augmented', qos.LATCHED).publish(
        conv.obstacle_array_msg(0, [('disc', DISC)], 0.3))
    odom = driver.create_publisher(Odometry, '/odom', qos.STREAM)
    safety = driver.create_publisher(SafetyStatus, '/safety/status', qos.STREAM)
    assert spin_until(executor, lambda: node.count_publishers('/odom') >= 1
                      and node.count_publishers('/safety/status') >= 1, 10.0)
    for k in range(steps):
        odom.publish(conv.odometry_msg(k * DT_NS, np.array([-6.0, -6.0, 0.0, 0.0])))
        status = SafetyStatus(augmented_stamp=conv.time_msg(0))
        status.header.stamp = conv.time_msg(k * DT_NS)
        safety.publish(status)
        assert spin_until(executor, lambda: len(stats) > k, 20.0), k
    return refs, stats


def test_gvf_planner_answers_every_step_with_a_reference(ros):
    context, executor, _ = ros
    node = planner(context, mode='gvf', v_max=2.0, a_max=2.0, horizon=5.0)
    refs, stats = drive(context, executor, node, 12)
    assert spin_until(executor, lambda: len(refs) >= 12, 5.0)
    stamps = [conv.stamp_ns(m.header.stamp) for m in refs.messages]
    assert stamps == [k * DT_NS for k in range(12)]
    for msg in refs.messages:
        assert msg.dt == 0.05 and len(msg.positions) == len(msg.velocities) == 101
        assert conv.stamp_ns(msg.obstacles_stamp) == 0
        assert np.hypot(msg.positions[0].x + 6.0, msg.positions[0].y + 6.0) < 1e-9
    found = [m for m in refs.messages if m.status != 'no_path']
    assert found, 'no path in 12 steps of 100 iterations'
    last = found[-1]
    assert last.status in ('reached', 'length')
    pts = np.array([[p.x, p.y] for p in last.positions])
    speed = np.array([np.hypot(v.x, v.y) for v in last.velocities])
    assert speed.max() <= 2.0 + 1e-9 and speed[-1] > 0.5     # under way, within v_max
    clearance = [PolygonSet([DISC]).nearest(p)[0] for p in pts]
    assert min(clearance) > 0.1                               # outside the repulsive boundary
    travelled = np.hypot(*np.diff(pts, axis=0).T).sum()
    assert 3.0 < travelled <= 2.0 * 5.0 + 1e-6                # at most v_max times the horizon
    # the reference heads for the goal
    assert np.hypot(*(pts[-1] - [6.0, 5.0])) < np.hypot(*(pts[0] - [6.0, 5.0])) - 3.0


def test_waypoint_planner_publishes_no_reference(ros):
    context, executor, _ = ros
    node = planner(context)
    refs, stats = drive(context, executor, node, 3)
    assert len(stats) >= 3 and len(refs) == 0
    assert node.count_publishers('/guidance/reference') == 0
