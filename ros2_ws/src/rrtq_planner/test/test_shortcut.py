"""Path shortening: never longer, never colliding, and taut where the optimum is known."""

import math

import numpy as np
import pytest
from shapely.geometry import LineString, Polygon

from rrtq_planner.geometry import ObstacleMap, points_in_polygon
from rrtq_planner.routes import grow
from rrtq_planner.rrtx import RRTX, RRTXConfig
from rrtq_planner.shortcut import (EdgeSet, ShortcutConfig, Shortener, outward_corners,
                                   path_length, shortcut_vertices, simplify)
from rrtq_testing import paths as vo

SQUARE = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def free(path, polygons):
    obstacles = ObstacleMap()
    for i, poly in enumerate(polygons):
        obstacles.add(str(i), poly)
    return bool(np.all(obstacles.segments_free(path[:-1], path[1:])))


def test_wraps_a_square_tautly():
    path = np.array([[-5.0, 0.0], [-3.0, 4.0], [0.0, 6.0], [3.0, 3.0], [5.0, 0.0]])
    out = simplify(path, [SQUARE])
    taut = 2.0 * math.hypot(4.0, 1.0) + 2.0
    assert out[0].tolist() == [-5.0, 0.0] and out[-1].tolist() == [5.0, 0.0]
    assert path_length(out) == pytest.approx(taut, abs=1e-5)
    assert free(out, [SQUARE])
    assert min(LineString(out).distance(Polygon(SQUARE)), 1.0) > 0.0


def test_straight_line_when_visible():
    path = np.array([[-5.0, 3.0], [0.0, 8.0], [5.0, 3.0]])
    out = simplify(path, [SQUARE])
    assert out.tolist() == [[-5.0, 3.0], [5.0, 3.0]]


def test_colliding_or_touching_input_is_returned_unchanged():
    through = np.array([[-5.0, 0.0], [0.0, 0.5], [5.0, 0.0]])
    assert np.array_equal(simplify(through, [SQUARE]), through)
    # Touching a vertex counts as collision (closed sets).
    touching = np.array([[-5.0, 3.0], [1.0, 1.0], [5.0, 3.0]])
    assert np.array_equal(simplify(touching, [SQUARE]), touching)


def test_outward_corners_are_free_convex_corners():
    l_shape = np.array([[0, 0], [4, 0], [4, 4], [3, 4], [3, 1], [0, 1]], float)
    corners = outward_corners([l_shape], 1e-6)
    assert len(corners) == 5  # (3, 1) is reflex
    assert not points_in_polygon(corners, l_shape).any()
    assert np.allclose(np.sort(np.round(corners, 4), axis=0),
                       np.sort(np.round(np.delete(l_shape, 4, axis=0), 4), axis=0))


def test_greedy_shortcut_keeps_a_subsequence():
    path = np.array([[-5.0, 0.0], [-4.0, 2.0], [-3.0, 4.0], [0.0, 6.0], [3.0, 3.0], [5.0, 0.0]])
    out = shortcut_vertices(path, EdgeSet([SQUARE]))
    assert out[0].tolist() == [-5.0, 0.0] and out[-1].tolist() == [5.0, 0.0]
    assert all(any(np.array_equal(p, q) for q in path) for p in out)
    assert path_length(out) <= path_length(path)


@pytest.mark.parametrize('seed', [11, 12, 13, 14])
def test_rrtx_paths_get_shorter_and_stay_clear(seed):
    polys, start, goal = vo.random_forest(seed)
    grown = grow(polys, 0.5)
    cfg = RRTXConfig(goal=tuple(goal), bounds=(-51.0, 51.0, -51.0, 51.0), robot_radius=0.5)
    planner = RRTX(cfg, np.random.default_rng(seed))
    for i, poly in enumerate(grown):
        planner.add_obstacle(str(i), poly)
    planner.set_robot(start)
    planner.run(800)
    raw = planner.path()
    assert len(raw)
    out = Shortener(grown).simplify(raw)
    assert np.array_equal(out[0], raw[0]) and np.array_equal(out[-1], raw[-1])
    assert path_length(out) <= path_length(raw) + 1e-12
    assert free(out, grown)
    assert vo.clearance(out, polys) >= 0.5
    optimum, _ = vo.shortest_path(vo.grow(polys, 0.5), start, goal)
    assert path_length(out) >= optimum - 1e-6


def test_bneck_detour_becomes_the_optimum():
    polys = vo.read_otte(vo.OTTE / 'BNeck.txt')
    grown = grow(polys, 0.5)
    # A detour around the right end of the wall, far from taut.
    path = np.array([[0.0, 40.0], [30.0, 20.0], [45.0, 5.0], [45.0, -5.0], [20.0, -30.0],
                     [0.0, -40.0]])
    assert free(path, grown)
    out = simplify(path, grown)
    optimum, _ = vo.shortest_path(vo.grow(polys, 0.5), (0.0, 40.0), (0.0, -40.0))
    assert path_length(out) == pytest.approx(optimum, rel=2e-4)
    assert vo.clearance(out, polys) >= 0.5


def test_config_is_validated():
    with pytest.raises(ValueError):
        ShortcutConfig(push=0.0)
    with pytest.raises(ValueError):
        ShortcutConfig(rounds=-1)
