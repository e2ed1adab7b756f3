"""Closed-set segment/point tests against polygons, and the keyed queue."""

import numpy as np
import pytest

from rrtq_planner.geometry import (
    ObstacleMap,
    clean_polygon,
    points_in_polygon,
    segments_cross_edges,
    segments_hit_polygon,
)
from rrtq_planner.heap import KeyedQueue

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])


def seg(p, q):
    return np.array([p], dtype=float), np.array([q], dtype=float)


@pytest.mark.parametrize(
    ("p", "q", "expected"),
    [
        ((-1, 1), (3, 1), True),  # crosses
        ((-1, 3), (3, 3), False),  # passes above
        ((-1, 2), (3, 2), True),  # runs along the top edge
        ((2, 2), (4, 4), True),  # touches a vertex
        ((0.5, 0.5), (1.5, 1.5), True),  # entirely inside
        ((2.0, -1.0), (2.0, 0.0), True),  # ends on a corner
        ((2.5, -1.0), (2.5, 3.0), False),  # parallel, outside
        ((3.0, 0.0), (4.0, 0.0), False),  # colinear with an edge, disjoint
    ],
)
def test_segment_against_closed_square(p, q, expected):
    a, b = seg(p, q)
    assert segments_hit_polygon(a, b, SQUARE)[0] == expected
    assert segments_hit_polygon(b, a, SQUARE)[0] == expected
    obstacles = ObstacleMap()
    obstacles.add("sq", SQUARE)
    assert obstacles.segments_free(a, b)[0] == (not expected)
    if obstacles.point_free(a[0]):
        assert obstacles.segments_free_from(a[0], b)[0] == (not expected)


def test_points_in_polygon_counts_boundary_as_inside():
    pts = np.array([[1, 1], [0, 1], [2, 2], [3, 1], [-0.001, 1], [1, 2.0001]], dtype=float)
    np.testing.assert_array_equal(
        points_in_polygon(pts, SQUARE), [True, True, True, False, False, False]
    )


def test_cross_edges_matches_brute_force_sampling():
    rng = np.random.default_rng(0)
    p = rng.uniform(-3, 3, (200, 2))
    q = rng.uniform(-3, 3, (200, 2))
    hit = segments_hit_polygon(p, q, SQUARE)
    t = np.linspace(0.0, 1.0, 2001)[:, None, None]
    samples = p[None] + t * (q - p)[None]
    inside = (
        (samples[..., 0] >= 0)
        & (samples[..., 0] <= 2)
        & (samples[..., 1] >= 0)
        & (samples[..., 1] <= 2)
    ).any(axis=0)
    # Dense sampling can only miss grazing hits, never invent one.
    assert not np.any(inside & ~hit)
    assert np.mean(hit == inside) > 0.98


def test_clean_polygon_drops_repeated_vertex_and_rejects_bad_shapes():
    closed = np.vstack((SQUARE, SQUARE[:1]))
    assert clean_polygon(closed).shape == (4, 2)
    with pytest.raises(ValueError):
        clean_polygon(np.zeros((2, 2)))
    with pytest.raises(ValueError):
        clean_polygon(np.zeros((4, 3)))


def test_obstacle_map_queries_and_removal():
    obstacles = ObstacleMap()
    obstacles.add("a", SQUARE)
    obstacles.add("b", SQUARE + 10.0)
    assert not obstacles.point_free(np.array([11.0, 11.0]))
    obstacles.remove("b")
    assert obstacles.point_free(np.array([11.0, 11.0]))
    ends = np.array([[5.0, 1.0], [5.0, 5.0], [-5.0, 1.0]])
    np.testing.assert_array_equal(
        obstacles.segments_free_from(np.array([1.0, 5.0]), ends), [True, True, True]
    )
    np.testing.assert_array_equal(
        obstacles.segments_free_from(np.array([-1.0, 1.0]), ends), [False, False, True]
    )
    assert not segments_cross_edges(*seg((5, 5), (6, 6)), SQUARE, np.roll(SQUARE, -1, 0)).any()


def test_keyed_queue_orders_updates_and_removes():
    q = KeyedQueue(capacity=2)
    for node, key in [(3, 5.0), (7, 1.0), (1, 3.0), (9, 3.0)]:
        q.push(node, key, key)
    q.push(3, 0.5, 0.5)  # decrease-key
    q.push(7, 4.0, 4.0)  # increase-key
    q.remove(1)
    assert len(q) == 3 and 1 not in q and 9 in q
    assert q.top_key() == (0.5, 0.5)
    assert [q.pop() for _ in range(3)] == [3, 9, 7]
    assert len(q) == 0 and q.top_key() is None
    with pytest.raises(IndexError):
        q.pop()


def test_keyed_queue_breaks_ties_on_second_key_then_insertion_order():
    q = KeyedQueue()
    q.push(0, 1.0, 2.0)
    q.push(1, 1.0, 1.0)
    q.push(2, 1.0, 2.0)
    assert [q.pop(), q.pop(), q.pop()] == [1, 0, 2]


def test_keyed_queue_stays_correct_under_many_stale_entries():
    rng = np.random.default_rng(3)
    q = KeyedQueue()
    truth = {}
    for _ in range(20000):
        node = int(rng.integers(0, 300))
        if rng.random() < 0.2:
            q.remove(node)
            truth.pop(node, None)
        else:
            key = float(rng.random())
            q.push(node, key, key)
            truth[node] = key
    assert len(q) == len(truth)
    assert set(q.nodes()) == set(truth)
    popped = [q.pop() for _ in range(len(truth))]
    keys = [truth[n] for n in popped]
    assert keys == sorted(keys)


def test_point_free_agrees_with_per_polygon_test():
    rng = np.random.default_rng(5)
    polys = [rng.uniform(-5, 5, (int(rng.integers(3, 8)), 2)) for _ in range(6)]
    polys.append(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [2.0, 1.0], [0.0, 4.0]]))  # concave
    obstacles = ObstacleMap()
    for i, poly in enumerate(polys):
        obstacles.add(str(i), poly)
    corners = [[2.0, 1.0], [1.0, 0.0], [2.0, 2.0], [3.0, 1.0]]
    pts = np.vstack((rng.uniform(-6, 6, (3000, 2)), corners))
    expected = np.zeros(len(pts), dtype=bool)
    for poly in polys:
        expected |= points_in_polygon(pts, poly)
    got = np.array([not obstacles.point_free(p) for p in pts])
    np.testing.assert_array_equal(got, expected)


def test_config_ball_radius_and_validation():
    from rrtq_planner.rrtx_config import RRTXConfig

    cfg = RRTXConfig(goal=(0.0, 0.0), bounds=(-50.0, 50.0, -50.0, 50.0), steer_distance=5.0)
    # 10 % above 2 (1 + 1/2)^(1/2) (mu / pi)^(1/2) with mu = 100 m x 100 m.
    assert cfg.gamma == pytest.approx(1.1 * 2.0 * np.sqrt(1.5) * np.sqrt(1e4 / np.pi))
    radii = [cfg.ball_radius(n) for n in (2, 10, 100, 1000, 10_000, 100_000)]
    assert all(r <= 5.0 for r in radii) and radii[-1] < radii[-2] < 5.0
    assert cfg.ball_radius(50_000) == pytest.approx(
        cfg.gamma * np.sqrt(np.log(50_000) / 50_000)
    )
    for bad in (
        {"steer_distance": 0.0},
        {"epsilon": -1.0},
        {"robot_sample_probability": 1.5},
        {"robot_radius": 60.0},
        {"ball_constant": -1.0},
    ):
        with pytest.raises(ValueError):
            RRTXConfig(goal=(0.0, 0.0), bounds=(-50.0, 50.0, -50.0, 50.0), **bad)
