"""Bench layouts and the visibility-graph optimum: determinism, keep-off, reachability."""

from __future__ import annotations

import math
import pathlib

import numpy as np
import pytest
import shapely
import yaml
from shapely.geometry import LineString, Polygon

from rrtq_bringup.bench.layouts import (LayoutConfig, LayoutError, generate_layout,
                                        layout_scenario)
from rrtq_bringup.scenario import load_scenario, parse_scenario
from rrtq_common.optimum import shortest_path

PAPER = pathlib.Path(__file__).resolve().parents[4] / 'scenarios' / 'rrtqx_paper.yaml'


@pytest.fixture(scope='module')
def paper():
    return load_scenario(PAPER), yaml.safe_load(PAPER.read_text())


def square(x0, y0, x1, y1):
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def test_optimum_wraps_a_square_exactly():
    # Around the top edge of [-1, 1]^2 from (-3, 0) to (3, 0): sqrt(5) + 2 + sqrt(5).
    opt = shortest_path([square(-1, -1, 1, 1)], [-3, 0], [3, 0])
    assert opt.length == pytest.approx(2 * math.sqrt(5) + 2, abs=1e-9)
    assert opt.path[0].tolist() == [-3, 0] and opt.path[-1].tolist() == [3, 0]
    # Grown by r = 0.5: tangents to the rounded corners, two arcs and the top edge; the
    # buffer's chords lie inside the exact sum, so the optimum is at most the exact one.
    grown = shortest_path([square(-1, -1, 1, 1)], [-3, 0], [3, 0], radius=0.5)
    arc = math.atan2(1, 2) + math.asin(0.5 / math.sqrt(5))
    exact = 2 * math.sqrt(5 - 0.25) + 2 + 2 * 0.5 * arc
    assert exact * (1 - 1e-3) < grown.length <= exact
    assert shortest_path([], [-3, 0], [3, 0]).length == pytest.approx(6.0)


def test_optimum_respects_bounds_and_reports_unreachable_goals():
    wall = square(-1, -10, 1, 1)
    # In bounds y <= 2 the way round the top is open; with y <= 0.5 there is none.
    assert shortest_path([wall], [-3, 0], [3, 0], bounds=((-5, 5), (-5, 2))).reachable
    assert not shortest_path([wall], [-3, 0], [3, 0], bounds=((-5, 5), (-5, 0.5))).reachable
    ring = [square(2, -2, 4, -1), square(2, 1, 4, 2), square(2, -2, 2.5, 2), square(3.5, -2, 4, 2)]
    assert not shortest_path(ring, [-3, 0], [3, 0]).reachable          # goal walled in
    assert not shortest_path([square(-4, -1, -2, 1)], [-3, 0], [3, 0]).reachable  # start inside


def test_layouts_are_deterministic_per_seed(paper):
    scenario, _ = paper
    a, b = generate_layout(scenario, 11), generate_layout(scenario, 11)
    assert a.obstacles == b.obstacles and a.optimum.length == b.optimum.length
    assert generate_layout(scenario, 12).obstacles != a.obstacles


@pytest.mark.parametrize('seed', range(12))
def test_layouts_keep_off_start_and_goal_and_leave_the_goal_reachable(paper, seed):
    scenario, document = paper
    config = LayoutConfig()
    layout = generate_layout(scenario, seed, config)
    # As the simulator will see it: the document loads and holds the layout.
    sc = parse_scenario(layout_scenario(document, layout, f'bench-{seed}'), str(PAPER))
    assert sc.seed == seed and len(sc.obstacles) == config.obstacles
    known = [o for o in sc.obstacles if o.known]
    appearing = [o for o in sc.obstacles if not o.known]
    assert len(known) == 2 and all(o.appear_at == 0.0 for o in known)
    assert all(o.appear_at >= config.earliest for o in appearing)
    keep_off = sc.robot_radius + config.end_clearance
    for o in sc.obstacles:
        shape = Polygon(o.polygon)
        for point in (sc.start, sc.goal):
            assert shape.distance(shapely.Point(point)) > keep_off
    # The optimum is a real path: in bounds, clear of every obstacle by the robot radius
    # (up to the growth's chords), and no shorter than the straight line.
    path = layout.optimum.path
    (x0, x1), (y0, y1) = sc.bounds
    assert np.all((path[:, 0] >= x0) & (path[:, 0] <= x1) & (path[:, 1] >= y0) & (path[:, 1] <= y1))
    line = LineString(path)
    assert min(line.distance(Polygon(o.polygon)) for o in sc.obstacles) > 0.99 * sc.robot_radius
    assert layout.optimum.length >= np.hypot(*(sc.goal - sc.start)) - 1e-9
    assert layout.optimum.length == pytest.approx(float(np.sum(np.hypot(*np.diff(path, axis=0).T))))


def test_appearing_obstacles_lie_about_the_route(paper):
    scenario, _ = paper
    config = LayoutConfig(obstacles=40, known_fraction=0.0, route_offset=0.5)
    layout = generate_layout(scenario, 3, config)
    route = LineString(layout.route.path)
    centres = [e['circle']['center'] if 'circle' in e else np.mean(e['polygon'], axis=0)
               for e in layout.obstacles]
    offsets = [route.distance(shapely.Point(c)) for c in centres]
    assert np.median(offsets) < 1.0 and max(offsets) < 3.0


def test_no_reachable_layout_is_bad_input():
    # A 2 m corridor: any 3 m obstacle grown by the 0.5 m robot closes it.
    corridor = parse_scenario({'bounds': {'x': [-10, 10], 'y': [-1, 1]}, 'start': [-9, 0],
                               'goal': [9, 0], 'robot_radius': 0.5}, 'corridor.yaml')
    with pytest.raises(LayoutError, match='corridor.yaml.*seed 4'):
        generate_layout(corridor, 4, LayoutConfig(obstacles=1, known_fraction=1.0,
                                                  size=(3.0, 3.0), attempts=5))
