"""Properties of the RRT^X core: tree invariants and exact repair.

Every check compares the planner with something computed independently:
Dijkstra (scipy) over the planner's own current edges, a brute-force
collision check of the path, or a snapshot taken before an obstacle change
(rrtq_testing.rrtx_checks).
"""

import time

import numpy as np
import pytest

from rrtq_planner.geometry import segments_hit_polygon
from rrtq_planner.rrtx import RRTX, PlanStatus, RRTXConfig
from rrtq_testing.rrtx_checks import (assert_invariants, assert_matches_dijkstra, assert_path_clear,
                                      dijkstra_to_goal, inside_convex, snapshot)

BOUNDS = (-20.0, 20.0, -20.0, 20.0)
GOAL = (15.0, 15.0)
START = (-15.0, -15.0)
STATIC = {
    "s1": np.array([[-8.0, -6.0], [-2.0, -6.0], [-2.0, -1.0], [-8.0, -1.0]]),
    "s2": np.array([[3.0, 2.0], [9.0, 4.0], [6.0, 9.0]]),
}


def box(cx, cy, hx, hy):
    return np.array(
        [[cx - hx, cy - hy], [cx + hx, cy - hy], [cx + hx, cy + hy], [cx - hx, cy + hy]]
    )


def build(seed=0, eps=0.0, iterations=1200, obstacles=STATIC, delta=3.0, path_bias=0.0):
    cfg = RRTXConfig(goal=GOAL, bounds=BOUNDS, steer_distance=delta, epsilon=eps,
                     path_bias=path_bias)
    planner = RRTX(cfg, np.random.default_rng(seed))
    for oid, poly in obstacles.items():
        planner.add_obstacle(oid, poly)
    planner.set_robot(START)
    planner.run(iterations)
    assert planner.status is PlanStatus.FOUND
    return planner


def test_invariants_hold_while_growing_and_repairing():
    # delta well above r(n), so that the ball shrinks and culling happens.
    planner = build(seed=1, iterations=600, delta=10.0)
    assert planner.radius < 10.0
    originals = {v: planner.neighbors(v)["out_original"] for v in range(planner.node_count)}
    assert_invariants(planner)
    planner.add_obstacle("wall", box(0.0, 0.0, 1.0, 12.0))
    assert_invariants(planner)
    planner.run(300)
    planner.remove_obstacle("s1")
    assert_invariants(planner)
    for v, before in originals.items():  # N0+ never shrinks
        assert planner.neighbors(v)["out_original"] == before
    r = planner.radius
    pos = planner.positions
    for v in range(planner.node_count):
        planner.cull_neighbors(v)
        for u in planner.neighbors(v)["out_running"]:
            assert np.linalg.norm(pos[u] - pos[v]) <= r or planner.parents[v] == u
    assert not planner.graph.eback[: planner.graph.ne].all()  # some edges were culled
    assert_invariants(planner)
    assert_matches_dijkstra(planner)


@pytest.mark.parametrize("eps, path_bias", [(0.0, 0.0), (0.5, 0.0), (0.0, 0.3)])
def test_cost_equals_dijkstra_through_obstacle_changes(eps, path_bias):
    planner = build(seed=2, eps=eps, path_bias=path_bias)
    assert_matches_dijkstra(planner)
    path = planner.path()
    mid = path[len(path) // 2]
    changes = [
        ("add", "block", box(mid[0], mid[1], 2.0, 2.0)),
        ("add", "bar", box(-5.0, 8.0, 6.0, 0.5)),
        ("remove", "s2", None),
        ("remove", "block", None),
        ("add", "s2", STATIC["s2"]),
        ("remove", "bar", None),
    ]
    for op, oid, poly in changes:
        if op == "add":
            planner.add_obstacle(oid, poly)
        else:
            planner.remove_obstacle(oid)
        assert_matches_dijkstra(planner)
        planner.run(150)
        assert_matches_dijkstra(planner)


def test_blocking_obstacle_is_repaired_collision_free():
    planner = build(seed=3)
    path = planner.path()
    before = planner.cost()
    # A box across the middle of the current path.
    mid = path[len(path) // 2]
    block = box(mid[0], mid[1], 2.5, 2.5)
    assert segments_hit_polygon(path[:-1], path[1:], block).any()
    planner.add_obstacle("block", block)
    assert planner.status is PlanStatus.FOUND
    assert planner.cost() > before
    dist = assert_matches_dijkstra(planner)
    to_vbot = np.linalg.norm(np.subtract(START, planner.positions[planner.vbot]))
    assert planner.cost() == pytest.approx(dist[planner.vbot] + to_vbot)
    repaired = planner.path()
    assert_path_clear(repaired, [block, *STATIC.values()])
    seg_cost = np.sum(np.linalg.norm(np.diff(repaired, axis=0), axis=1))
    assert seg_cost == pytest.approx(planner.cost(), abs=1e-9)


def test_obstacle_touching_no_edge_changes_nothing():
    planner = build(seed=4)
    gr = planner.graph
    rng = np.random.default_rng(0)
    a = gr.pos[gr.ea[: gr.ne]]
    b = gr.pos[gr.eb[: gr.ne]]
    for _ in range(2000):  # find a small triangle in a gap of the graph
        c = rng.uniform(-19, 19, 2)
        tri = c + np.array([[0.0, 0.0], [0.15, 0.0], [0.0, 0.15]])
        if not segments_hit_polygon(a, b, tri).any():
            break
    else:
        pytest.fail("no empty spot found")
    before = snapshot(planner)
    planner.add_obstacle("tiny", tri)
    after = snapshot(planner)
    for key in before:
        np.testing.assert_array_equal(before[key], after[key])


@pytest.mark.parametrize("delta", [3.0, 10.0])
def test_add_then_remove_restores_costs_exactly(delta):
    planner = build(seed=5, delta=delta)
    for v in range(planner.node_count):  # settle culling at the current r(n)
        planner.cull_neighbors(v)
    before = snapshot(planner)
    path = planner.path()
    mid = path[len(path) // 3]
    planner.add_obstacle("block", box(mid[0], mid[1], 3.0, 3.0))
    assert planner.cost() > before["cost"]
    planner.remove_obstacle("block")
    after = snapshot(planner)
    np.testing.assert_array_equal(before["ecost"], after["ecost"])
    assert_matches_dijkstra(planner)
    changed = np.flatnonzero(before["eback"] != after["eback"])
    if planner.radius == delta:
        # r(n) = delta: no edge is longer than the ball, nothing can be culled,
        # and the graph and g(v_bot) come back bit for bit.
        assert changed.size == 0
        assert after["g"][planner.vbot] == before["g"][planner.vbot]
        assert after["cost"] == before["cost"]
    else:
        # With r(n) < delta a parent edge may be longer than r(n); once the
        # repair re-parents its tail, Algorithm 3 culls it for good, so the
        # restored cost can only be the same or higher -- and still exact.
        assert np.all(planner.graph.elen[changed] > planner.radius)
        assert after["g"][planner.vbot] >= before["g"][planner.vbot]


def test_overlapping_obstacles_keep_shared_edges_blocked():
    planner = build(seed=6)
    path = planner.path()
    mid = path[len(path) // 2]
    first = box(mid[0] - 1.0, mid[1], 2.0, 2.0)
    second = box(mid[0] + 1.0, mid[1], 2.0, 2.0)
    planner.add_obstacle("first", first)
    planner.add_obstacle("second", second)
    planner.remove_obstacle("first")
    gr = planner.graph
    a = gr.pos[gr.ea[: gr.ne]]
    b = gr.pos[gr.eb[: gr.ne]]
    blocked = np.zeros(gr.ne, dtype=bool)
    for poly in [second, *STATIC.values()]:
        blocked |= segments_hit_polygon(a, b, poly)
    np.testing.assert_array_equal(np.isinf(gr.ecost[: gr.ne]), blocked)
    assert_matches_dijkstra(planner)
    assert_path_clear(planner.path(), [second, *STATIC.values()])


def test_enclosed_goal_reports_no_path_and_recovers():
    planner = build(seed=7, iterations=800)
    gx, gy = GOAL
    walls = {
        "n": box(gx, gy + 3.0, 3.5, 0.5),
        "s": box(gx, gy - 3.0, 3.5, 0.5),
        "e": box(gx + 3.0, gy, 0.5, 3.5),
        "w": box(gx - 3.0, gy, 0.5, 3.5),
    }
    t0 = time.perf_counter()
    planner.update_obstacles(added=walls)
    assert planner.status is PlanStatus.NO_PATH
    assert planner.cost() == np.inf and planner.path().shape == (0, 2)
    planner.run(300)
    assert time.perf_counter() - t0 < 10.0
    assert planner.status is PlanStatus.NO_PATH
    planner.remove_obstacle("w")
    assert planner.status is PlanStatus.FOUND
    assert_matches_dijkstra(planner)
    assert_path_clear(planner.path(), [walls["n"], walls["s"], walls["e"], *STATIC.values()])


def test_fixed_seed_gives_same_tree_and_path():
    runs = []
    for _ in range(2):
        planner = build(seed=8, iterations=500)
        planner.add_obstacle("x", box(0.0, 0.0, 3.0, 3.0))
        planner.run(100)
        runs.append(planner)
    a, b = runs
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.parents, b.parents)
    np.testing.assert_array_equal(a.g, b.g)
    np.testing.assert_array_equal(a.path(), b.path())
    other = build(seed=9, iterations=500)
    assert not np.array_equal(other.positions[:50], a.positions[:50])


def test_robot_moves_along_path_and_retargets_when_cut_off():
    planner = build(seed=10)
    path = planner.path()
    cost = planner.cost()
    planner.set_robot(path[1])  # reach the first waypoint: v_bot advances
    np.testing.assert_array_equal(planner.path()[0], path[1])
    assert planner.cost() == pytest.approx(cost - np.linalg.norm(path[1] - path[0]), abs=1e-9)
    halfway = 0.5 * (planner.path()[0] + planner.path()[1])
    planner.set_robot(halfway)
    target = planner.positions[planner.vbot]
    # Block the robot's current edge just ahead of it.
    ahead = halfway + 0.6 * (target - halfway)
    planner.add_obstacle("ahead", box(ahead[0], ahead[1], 0.2, 0.2))
    assert planner.status is PlanStatus.FOUND
    new_path = planner.path()
    np.testing.assert_array_equal(new_path[0], halfway)
    assert_path_clear(new_path, [box(ahead[0], ahead[1], 0.2, 0.2), *STATIC.values()])


def test_a_robot_stalled_short_of_its_waypoint_moves_on_to_the_next_one_it_sees():
    """A robot held off v_bot (a gust its controller cannot overcome) that comes no closer
    for stall_time: v_bot moves on to its parent when the robot sees it, not before, and not
    through an obstacle; the path then starts at the robot and stays clear."""
    planner = build(seed=10)
    path = planner.path()
    first, second = path[1], path[2]
    along = (second - first) / np.linalg.norm(second - first)
    held = first - 1.6 * np.array([-along[1], along[0]]) - 0.05 * along   # beside it, not past
    stall = planner.config.stall_time
    for t in np.arange(0.0, stall, 0.05):
        planner.set_robot(held - 0.01 * abs(np.sin(t)) * along, t)   # it wobbles, no closer
        np.testing.assert_array_equal(planner.positions[planner.vbot], first)
    planner.set_robot(held, stall + 0.05)
    np.testing.assert_array_equal(planner.positions[planner.vbot], second)
    assert planner.status is PlanStatus.FOUND
    np.testing.assert_array_equal(planner.path()[0], held)
    assert_path_clear(planner.path(), list(STATIC.values()))
    # Progress resets the clock; a parent behind an obstacle is not taken.
    again = build(seed=10)
    wall = box(*(0.5 * (held + second)), 0.3, 0.3)
    again.add_obstacle("wall", wall)
    assert segments_hit_polygon(held[None], second[None], wall).any()
    for t in np.arange(0.0, 2.0 * stall, 0.05):
        again.set_robot(held, t)
        assert not np.array_equal(again.positions[again.vbot], second)
    assert again.status is PlanStatus.FOUND
    assert_path_clear(again.path(), [wall, *STATIC.values()])
    closer = build(seed=10)
    for t in np.arange(0.0, 1.5 * stall, 0.05):
        closer.set_robot(held + min(t / stall, 1.0) * 0.5 * (first - held), t)
    np.testing.assert_array_equal(closer.positions[closer.vbot], first)


def test_a_robot_held_while_the_goal_is_cut_off_is_not_stalled():
    """Without a path the controller holds the robot (an empty plan): that is not a stall.
    The clock starts when the path is back, and v_bot moves on one stall_time later."""
    planner = build(seed=10)
    path = planner.path()
    first, second = path[1], path[2]
    along = (second - first) / np.linalg.norm(second - first)
    held = first - 1.6 * np.array([-along[1], along[0]]) - 0.05 * along
    stall = planner.config.stall_time
    fence = {"fs": box(15.0, 12.0, 3.2, 0.2), "fn": box(15.0, 18.0, 3.2, 0.2),
             "fw": box(12.0, 15.0, 0.2, 3.2), "fe": box(18.0, 15.0, 0.2, 3.2)}
    planner.set_robot(held, 0.0)
    for oid, poly in fence.items():
        planner.add_obstacle(oid, poly)
    for t in np.arange(0.05, 2.0 * stall, 0.05):
        planner.set_robot(held, t)
        assert planner.status is PlanStatus.NO_PATH
    for oid in fence:
        planner.remove_obstacle(oid)
    back = 2.0 * stall
    for t in np.arange(back, back + stall - 0.05, 0.05):
        planner.set_robot(held, t)
        assert planner.status is PlanStatus.FOUND
        np.testing.assert_array_equal(planner.positions[planner.vbot], first)
    planner.set_robot(held, back + stall + 0.05)
    np.testing.assert_array_equal(planner.positions[planner.vbot], second)


@pytest.mark.parametrize(
    ("seed", "eps", "delta"), [(11, 0.0, 3.0), (12, 0.3, 3.0), (13, 0.0, 8.0)]
)
def test_random_obstacle_and_robot_sequences_stay_exact(seed, eps, delta):
    rng = np.random.default_rng(seed)
    planner = build(seed=seed, eps=eps, iterations=700, delta=delta)
    present = dict(STATIC)
    for step in range(25):
        op = rng.choice(["add", "remove", "move", "grow"], p=[0.35, 0.25, 0.2, 0.2])
        if op == "add":
            c = rng.uniform(-18, 18, 2)
            poly = box(c[0], c[1], *rng.uniform(0.3, 4.0, 2))
            if inside_convex(np.array([planner.robot, GOAL]), poly).any():
                continue
            present[f"r{step}"] = poly
            planner.add_obstacle(f"r{step}", poly)
        elif op == "remove" and present:
            oid = sorted(present)[int(rng.integers(len(present)))]
            del present[oid]
            planner.remove_obstacle(oid)
        elif op == "move" and planner.status is PlanStatus.FOUND:
            path = planner.path()
            planner.set_robot(path[0] + rng.uniform(0.2, 1.0) * (path[1] - path[0]))
        else:
            planner.run(100)
        if planner.status is PlanStatus.FOUND:
            assert_matches_dijkstra(planner)
            assert_path_clear(planner.path(), list(present.values()), spacing=0.02)
        else:
            dist, _ = dijkstra_to_goal(planner)
            assert not planner.robot_edge_free or dist[planner.vbot] == np.inf
    assert_invariants(planner)


def test_moving_an_obstacle_and_batched_updates():
    planner = build(seed=14)
    path = planner.path()
    mid = path[len(path) // 2]
    planner.add_obstacle("mover", box(mid[0], mid[1], 2.0, 2.0))
    moved = box(mid[0] + 6.0, mid[1] - 6.0, 2.0, 2.0)
    planner.add_obstacle("mover", moved)  # same id: a move
    assert planner.obstacles.ids() == ["s1", "s2", "mover"]
    assert_matches_dijkstra(planner)
    assert_path_clear(planner.path(), [moved, *STATIC.values()])
    grown = box(mid[0] + 6.0, mid[1] - 6.0, 2.6, 2.6)
    planner.add_obstacle("mover", grown)  # regrown in place: only new blocks
    gr = planner.graph
    a = gr.pos[gr.ea[: gr.ne]]
    b = gr.pos[gr.eb[: gr.ne]]
    blocked = np.zeros(gr.ne, dtype=bool)
    for poly in [grown, *STATIC.values()]:
        blocked |= segments_hit_polygon(a, b, poly)
    np.testing.assert_array_equal(np.isinf(gr.ecost[: gr.ne]), blocked)
    assert_matches_dijkstra(planner)
    extra = box(mid[0], mid[1], 1.0, 1.0)
    planner.update_obstacles(added={"extra": extra}, removed=["mover", "s1"])
    assert_matches_dijkstra(planner)
    assert_path_clear(planner.path(), [extra, STATIC["s2"]])
    with pytest.raises(KeyError):
        planner.remove_obstacle("nope")
    assert_invariants(planner)


def test_goal_enclosed_from_the_start_keeps_searching_without_hanging():
    gx, gy = GOAL
    ring = {
        "n": box(gx, gy + 3.0, 3.5, 0.5),
        "s": box(gx, gy - 3.0, 3.5, 0.5),
        "e": box(gx + 3.0, gy, 0.5, 3.5),
        "w": box(gx - 3.0, gy, 0.5, 3.5),
    }
    cfg = RRTXConfig(goal=GOAL, bounds=BOUNDS, steer_distance=3.0)
    planner = RRTX(cfg, np.random.default_rng(15))
    planner.update_obstacles(added=ring)
    planner.set_robot(START)
    planner.run(400)
    assert planner.status is PlanStatus.SEARCHING
    assert planner.cost() == np.inf and planner.path().shape == (0, 2)
    planner.remove_obstacle("s")
    planner.run(1500)
    assert planner.status is PlanStatus.FOUND
    assert_matches_dijkstra(planner)
    assert_path_clear(planner.path(), [ring["n"], ring["e"], ring["w"]])


def _share_near_bends(planner, before):
    """Share of the nodes added since ``before`` within r(n) of a bend of the path."""
    path = planner.path()
    seg = np.diff(path, axis=0)
    heading = np.arctan2(seg[:, 1], seg[:, 0])
    turn = np.abs((np.diff(heading) + np.pi) % (2 * np.pi) - np.pi)
    bends = path[1:-1][turn > 0.1]
    added = planner.positions[before:]
    dist = np.min(np.linalg.norm(added[:, None, :] - bends[None], axis=2), axis=1)
    return float(np.mean(dist < planner.radius))


def test_path_bias_samples_about_the_paths_bends_and_widens_the_ball():
    uniform = RRTXConfig(goal=GOAL, bounds=BOUNDS)
    biased = RRTXConfig(goal=GOAL, bounds=BOUNDS, path_bias=0.3)
    assert biased.ball_radius(5000) == pytest.approx(uniform.ball_radius(5000) / 0.7 ** 0.5)
    with pytest.raises(ValueError):
        RRTXConfig(goal=GOAL, bounds=BOUNDS, path_bias=1.0)
    shares = {}
    for bias in (0.0, 0.3):
        planner = build(seed=4, path_bias=bias, iterations=400)
        before = planner.node_count
        planner.run(600)
        shares[bias] = _share_near_bends(planner, before)
        assert_matches_dijkstra(planner)
    # Against the same planner with uniform samples (some biased samples are
    # steered, fall in obstacles or settle on other bends): clearly more at bends.
    assert shares[0.3] > 1.3 * shares[0.0], shares


def test_an_obstacle_that_shrinks_under_its_id_gives_its_edges_back():
    # The safety node's margin can shrink (conformal, learned_bound): the same id comes
    # back smaller, and the edges only the larger polygon blocked must be usable again.
    planner = build(seed=8)
    path = planner.path()
    mid = path[len(path) // 2]
    large, small = box(mid[0], mid[1], 3.0, 3.0), box(mid[0], mid[1], 0.5, 0.5)
    planner.update_obstacles(added={"grown": large})
    cost_large = planner.cost()
    planner.update_obstacles(added={"grown": small})
    gr = planner.graph
    a, b = gr.pos[gr.ea[: gr.ne]], gr.pos[gr.eb[: gr.ne]]
    blocked = np.zeros(gr.ne, dtype=bool)
    for poly in [small, *STATIC.values()]:
        blocked |= segments_hit_polygon(a, b, poly)
    np.testing.assert_array_equal(np.isinf(gr.ecost[: gr.ne]), blocked)
    assert_matches_dijkstra(planner)
    assert planner.cost() <= cost_large
    assert_path_clear(planner.path(), [small, *STATIC.values()])
