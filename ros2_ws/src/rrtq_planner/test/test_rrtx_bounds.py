"""The planner keeps inside the bounds shrunk by the margin: graph, paths, plans, `rrtq plan`.

The region is checked independently of the planner's own test: every live edge is
sampled at 21 points and each must lie in the shrunk box, every path segment every 5 mm
(the goal, the tree's root, may lie in the margin band: a goal near a wall; only its own
edges may leave the box).
"""

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from rrtq_common.lockstep import OnChange
from rrtq_planner.routes import plan
from rrtq_planner.rrtx import RRTX, PlanStatus, RRTXConfig
from rrtq_planner.safety import augment
from rrtq_planner.session import Budget, PlannerConfig, PlannerSession
from rrtq_planner.shortcut import Shortener

BOUNDS = (-10.0, 10.0, -10.0, 10.0)
# A bar from the top wall down to y = -6: the only way past it is the 4 m gap along the
# bottom wall, so the best path runs along that wall.
BAR = np.array([[-1.0, -6.0], [1.0, -6.0], [1.0, 10.0], [-1.0, 10.0]])


def shrunk(margin):
    x0, x1, y0, y1 = BOUNDS
    return np.array([x0 + margin, y0 + margin]), np.array([x1 - margin, y1 - margin])


def in_box(points, margin, tol=1e-9):
    lo, hi = shrunk(margin)
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    return np.all((pts >= lo - tol) & (pts <= hi + tol), axis=1)


def along(p, q, spacing=0.005):
    m = max(2, int(np.ceil(np.linalg.norm(q - p) / spacing)) + 1)
    return p + np.linspace(0.0, 1.0, m)[:, None] * (q - p)


def assert_graph_in_region(planner, margin):
    """Every node with a path and every unblocked edge lies in the shrunk box."""
    pos = planner.positions
    goal = planner.goal
    live = np.flatnonzero(np.isfinite(planner.lmc))
    live = live[live != goal]
    assert in_box(pos[live], margin).all()
    tail, head, cost = planner.edges()
    ok = np.isfinite(cost)
    tail, head = tail[ok], head[ok]
    # The goal's own edges may leave the box, only near the goal: their other end is in it.
    at_goal = (tail == goal) | (head == goal)
    assert in_box(pos[np.where(tail == goal, head, tail)[at_goal]], margin).all()
    a, b = pos[tail[~at_goal]], pos[head[~at_goal]]
    for s in np.linspace(0.0, 1.0, 21):
        assert in_box(a + s * (b - a), margin).all()


def assert_plan_in_region(waypoints, margin, goal):
    """The plan (the robot's next waypoint to the goal) lies in the box; the goal may not."""
    assert len(waypoints) >= 1 and np.array_equal(waypoints[-1], goal)
    inner = waypoints[:-1]
    assert in_box(inner, margin).all()
    for p, q in zip(inner[:-1], inner[1:]):
        assert in_box(along(p, q), margin).all()


def assert_cost_is_dijkstra(planner):
    tail, head, cost = planner.edges()
    ok = np.isfinite(cost)
    n = planner.node_count
    graph = csr_matrix((cost[ok], (head[ok], tail[ok])), shape=(n, n))
    dist = dijkstra(graph, indices=planner.goal)
    assert planner.g[planner.vbot] == pytest.approx(dist[planner.vbot], abs=1e-9)


def session(goal, seed):
    config = RRTXConfig(goal=goal, bounds=BOUNDS, steer_distance=3.0, max_nodes=1500)
    return PlannerSession(config, np.random.default_rng(seed),
                          PlannerConfig(bounds=BOUNDS, steer_distance=3.0, max_nodes=1500))


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_graph_and_plans_keep_the_margin_off_the_bounds_as_it_grows_and_shrinks(seed):
    """A robot starting in the corner, 0.3 m from both walls, a goal 0.6 m off the bottom
    wall behind a bar that leaves only a gap along that wall; the margin (robot radius
    0.5 + D_rob) grows and shrinks as the safety node's would, and the obstacles are grown
    by it. Throughout: the graph and the plan lie in the bounds shrunk by the margin, and
    the cost is Dijkstra's; the robot joins the tree at the box's nearest point, and later,
    in the band the grown margin leaves it in, plans on from where it is."""
    goal = (8.0, -9.4)
    s = session(goal, seed)
    robot = np.array([-9.7, -9.7])
    stamp = 0
    for margin in (0.5, 0.9, 1.4, 0.7, 1.1):
        stamp += 1
        grown = {'bar': augment(BAR, margin)}
        cycle = s.cycle(stamp, robot, OnChange(stamp, lambda grown=grown: grown.items()),
                        Budget(iterations=1000), margin)
        planner = s.planner
        assert planner.region.margin == margin
        assert cycle.plan.status is PlanStatus.FOUND, margin
        assert_graph_in_region(planner, margin)
        assert_plan_in_region(cycle.plan.waypoints, margin, goal)
        assert_cost_is_dijkstra(planner)
        # The path passes the bar through the gap, the margin off the bottom wall.
        path = planner.path()
        k = int(np.flatnonzero((path[:-1, 0] <= 0.0) & (path[1:, 0] > 0.0))[0])
        (xa, ya), (xb, yb) = path[k], path[k + 1]
        assert -10.0 + margin - 1e-9 <= ya + (yb - ya) * (0.0 - xa) / (xb - xa) <= -6.0 - margin
        if stamp == 1:
            # The robot joins from outside the box at the box's nearest point.
            assert np.array_equal(path[0], robot) and np.allclose(path[1], -9.5)
        # The robot moves a little along its plan, as a robot would between replans.
        step = cycle.plan.waypoints[0] - robot
        robot = robot + 0.3 * step / max(np.linalg.norm(step), 1e-9)


def test_robot_joining_from_outside_the_region_joins_at_its_nearest_point():
    """Before the robot joins the tree it is inserted where it is; from the margin band (or
    beyond the bounds) it joins at the box's nearest point instead, so no node lies
    outside."""
    config = RRTXConfig(goal=(5.0, 5.0), bounds=BOUNDS, steer_distance=3.0, robot_radius=0.5)
    for start in ((-9.8, 0.0), (-10.6, -10.4)):
        planner = RRTX(config, np.random.default_rng(4))
        planner.set_robot(start)
        planner.run(1500)
        assert planner.status is PlanStatus.FOUND
        assert in_box(np.delete(planner.positions, planner.goal, axis=0), 0.5).all()
        path = planner.path()
        assert np.array_equal(path[0], start)
        assert np.allclose(path[1], np.clip(start, -9.5, 9.5))
        assert_graph_in_region(planner, 0.5)


def test_a_robot_blown_out_of_the_bounds_is_sent_back_by_the_shortest_way():
    """A robot that has a plan and is blown out of the bounds plans back in: to the box's
    nearest point, then on; the plan is found at once (no failure), and once it is back
    in, v_bot moves on along the tree as before."""
    config = RRTXConfig(goal=(8.0, 8.0), bounds=BOUNDS, steer_distance=3.0, robot_radius=0.5)
    planner = RRTX(config, np.random.default_rng(5))
    planner.set_robot((-5.0, -5.0))
    planner.run(2000)
    assert planner.status is PlanStatus.FOUND
    out = np.array([-11.5, 2.0])
    planner.set_robot(out)
    assert planner.status is PlanStatus.FOUND
    path = planner.path()
    assert np.array_equal(path[0], out) and np.allclose(path[1], (-9.5, 2.0))
    assert_graph_in_region(planner, 0.5)
    entry = planner.vbot
    # Drifting along the wall while still outside keeps the same way back (no new entry).
    planner.set_robot((-10.8, 2.6))
    assert planner.vbot == entry
    # Back inside and past the entry, the robot goes on along the tree.
    planner.set_robot(planner.positions[planner.parents[entry]])
    assert planner.vbot != entry and planner.status is PlanStatus.FOUND


def test_a_goal_in_the_margin_band_stays_reachable():
    """The goal may be nearer a wall than the margin: it is the tree's root and keeps its
    edges; the rest of the plan keeps the margin."""
    goal = (0.0, 9.8)
    config = RRTXConfig(goal=goal, bounds=BOUNDS, steer_distance=3.0)
    planner = RRTX(config, np.random.default_rng(6))
    planner.update_obstacles(margin=1.0)
    planner.set_robot((0.0, -5.0))
    planner.run(1500)
    assert planner.status is PlanStatus.FOUND
    assert_plan_in_region(planner.path()[1:], 1.0, goal)
    assert_graph_in_region(planner, 1.0)


def test_shortcuts_keep_a_path_in_any_box_that_holds_its_waypoints():
    """shortcut.py only keeps waypoints and adds obstacle corners inside a bend's triangle,
    so a path whose waypoints lie in a box (convex) stays in it."""
    rng = np.random.default_rng(7)
    obstacles = [augment(BAR, 0.8), augment(np.array([[4.0, -4.0], [6.0, -4.0], [5.0, 0.0]]), 0.8)]
    short = Shortener(obstacles)
    for _ in range(40):
        config = RRTXConfig(goal=(8.0, rng.uniform(-8.5, 8.5)), bounds=BOUNDS,
                            steer_distance=3.0, robot_radius=1.5)
        planner = RRTX(config, rng)
        for i, poly in enumerate(obstacles):
            planner.add_obstacle(f'o{i}', poly)
        planner.set_robot((-8.0, rng.uniform(-8.5, 8.5)))
        planner.run(600)
        if planner.status is not PlanStatus.FOUND:
            continue
        path = short.simplify(planner.path())
        for p, q in zip(path[:-1], path[1:]):
            assert in_box(along(p, q), 1.5).all()


def test_rrtq_plan_from_the_margin_band_keeps_its_path_in_the_box():
    """`rrtq plan` with a start 0.2 m off a wall (robot radius 0.5): the path goes from the
    start to the box's nearest point, then stays in the bounds shrunk by the radius."""
    start, goal = np.array([-9.8, -8.0]), np.array([8.0, -8.0])
    result = plan([BAR], start, goal, BOUNDS, 0.5, 0.5, seed=3)
    path = result.path
    assert len(path) >= 3 and np.array_equal(path[0], start) and np.array_equal(path[-1], goal)
    assert np.allclose(path[1], (-9.5, -8.0))
    for p, q in zip(path[1:-1], path[2:]):
        assert in_box(along(p, q), 0.5).all()
