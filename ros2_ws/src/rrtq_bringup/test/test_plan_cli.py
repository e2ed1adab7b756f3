"""`rrtq plan`: clearance from the original polygons, cost against the exact optimum, exit codes."""

import json
import math

import numpy as np
import pytest
from shapely.geometry import LinearRing, Point, Polygon

from rrtq_bringup import plan_cli
from rrtq_planner.safety import grow_polygon
from rrtq_testing import paths as vo

DATA = vo.OTTE
RADIUS = 0.5


def run(capsys, *argv):
    code = plan_cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if out.strip() else None), err


def check_path(result, polygons, start, goal, radius=RADIUS, slack=1.03):
    """The issue's check: clearance >= R from the original polygons, cost <= 1.03 optimum."""
    path = np.array(result['path'])
    assert np.array_equal(path[0], start) and np.array_equal(path[-1], goal)
    assert vo.clearance(path, polygons) >= radius
    assert result['cost'] == pytest.approx(vo.length(path), abs=1e-9)
    assert result['cost'] <= result['rrtx_cost'] + 1e-9
    optimum, _ = vo.shortest_path(vo.grow(polygons, radius), start, goal)
    assert optimum - 1e-6 <= result['cost'] <= slack * optimum
    return result['cost'] / optimum


def test_bneck_goes_around_the_wall(capsys):
    code, result, _ = run(capsys, DATA / 'BNeck.txt', '--start', 0, 40, '--goal', 0, -40,
                          '--radius', RADIUS, '--time', 2)
    assert code == 0
    polys = vo.read_otte(DATA / 'BNeck.txt')
    check_path(result, polys, (0.0, 40.0), (0.0, -40.0))
    assert result['nodes'] > 100 and 1.5 < result['time_s'] < 10.0


def test_rand_static(capsys):
    code, result, _ = run(capsys, DATA / 'rand_Static.txt', '--start', 35, -40,
                          '--goal', -40, 40, '--radius', RADIUS, '--seed', 3)
    assert code == 0
    check_path(result, vo.read_otte(DATA / 'rand_Static.txt'), (35.0, -40.0), (-40.0, 40.0))


@pytest.mark.parametrize('seed', [101, 202, 303])
def test_random_forest(capsys, tmp_path, seed):
    polys, start, goal = vo.random_forest(seed)
    env = tmp_path / f'forest{seed}.txt'
    vo.write_otte(env, polys)
    code, result, _ = run(capsys, env, '--start', *start, '--goal', *goal,
                          '--radius', RADIUS, '--time', 2)
    assert code == 0
    # The file holds 6 decimals: judge against what the planner read.
    check_path(result, vo.read_otte(env), start, goal)


SCENARIO = """
name: plan-cli
bounds: {x: [-20, 20], y: [-20, 20]}
start: [-15, -15]
goal: [15, 15]
robot_radius: 0.8
obstacles:
  - {id: wall, polygon: [[-10, -2], [10, -2], [10, 2], [-10, 2]]}
  - {id: pillar, circle: {center: [8, 10], radius: 1.5}}
  - {id: late, polygon: [[-3, -12], [3, -12], [3, 12], [-3, 12]], appear_at: 5.0}
"""


def test_scenario_uses_obstacles_at_t0_bounds_and_robot_radius(capsys, tmp_path):
    env = tmp_path / 'plan.yaml'
    env.write_text(SCENARIO)
    code, result, _ = run(capsys, env, '--start', -15, -15, '--goal', 15, 15, '--time', 1)
    assert code == 0
    path = np.array(result['path'])
    assert np.all(np.abs(path) <= 20.0)
    square = [[-10, -2], [10, -2], [10, 2], [-10, 2]]
    from rrtq_common.geometry import polygon_from_circle
    present = [np.array(square, float), polygon_from_circle((8, 10), 1.5)]
    # The late wall would block x = -3..3 across y = -12..12; it does not exist at t = 0.
    check_path(result, present, (-15.0, -15.0), (15.0, 15.0), radius=0.8)


def test_no_path_when_the_goal_is_enclosed(capsys, tmp_path):
    walls = [np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float) for x0, x1, y0, y1 in
             ((-5, 5, 4, 5), (-5, 5, -5, -4), (-5, -4, -5, 5), (4, 5, -5, 5))]
    env = tmp_path / 'box.txt'
    vo.write_otte(env, walls)
    code, result, _ = run(capsys, env, '--start', -20, -20, '--goal', 0, 0, '--time', 0.5,
                          '--radius', RADIUS)
    assert code == 1
    assert result['path'] == [] and result['cost'] is None


@pytest.mark.parametrize('argv, names', [
    (['missing.txt', '--start', 0, 0, '--goal', 1, 1], 'missing.txt'),
    (['{bneck}', '--start', 0, 0, '--goal', 0, -40, '--radius', 0.5], '--start'),
    (['{bneck}', '--start', 0, 40, '--goal', -30, 0.3, '--radius', 0.5], '--goal'),
    (['{bneck}', '--start', 0, 40, '--goal', 0, -40, '--bounds', -50, 50, -30, 50], '--goal'),
    (['{bneck}', '--start', 0, 40, '--goal', 0, -40, '--bounds', 5, -5, -50, 50], '--bounds'),
    (['{bneck}', '--start', 0, 'north', '--goal', 0, -40], '--start'),
    (['{bneck}', '--start', 0, 40, '--goal', 0, 'nan'], '--goal'),
    (['{bneck}', '--start', 0, 40, '--goal', 0, -40, '--time', 0], '--time'),
    (['{bneck}', '--start', 0, 40, '--goal', 0, -40, '--radius', -1], '--radius'),
    (['{bneck}', '--start', 0, 40], '--goal'),
    (['{bad}', '--start', 0, 40, '--goal', 0, -40], 'bad.txt'),
    (['{yaml}', '--start', 0, 40, '--goal', 0, -40], 'broken.yaml'),
])
def test_bad_input_exits_2_naming_the_culprit(capsys, tmp_path, argv, names):
    bad = tmp_path / 'bad.txt'
    bad.write_text('2\n4\n0, 0\n1, 0\n1, 1\n')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('bounds: {x: [0, 1]}\nstart: [0, 0]\n')
    files = {'{bneck}': str(DATA / 'BNeck.txt'), '{bad}': str(bad), '{yaml}': str(broken)}
    argv = [files.get(str(a), a) for a in argv]
    code, result, err = run(capsys, *argv)
    assert code == 2
    assert result is None
    assert names in err


def test_grown_polygons_keep_the_radius_and_stay_tight():
    rng = np.random.default_rng(5)
    polys = vo.random_forest(7)[0] + [np.array([[0, 0], [4, 0], [4, 4], [3, 4], [3, 1], [0, 1]],
                                               float)]
    for poly in polys:
        r = float(rng.uniform(0.1, 2.0))
        grown = grow_polygon(poly, r)
        assert Polygon(poly).distance(LinearRing(grown)) >= r * (1 - 1e-12)
        # Every grown vertex (the farthest points) within r / cos(pi / 32) of the polygon.
        farthest = max(Point(v).distance(Polygon(poly)) for v in grown)
        assert farthest <= r / math.cos(math.pi / 32) + 1e-12
