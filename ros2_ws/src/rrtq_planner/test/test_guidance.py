"""Guiding level (VF-LPC §IV-A): the composite field's curve and reference, checked from outside.

Ground truth that does not come from the code under test: clearance by
``rrtq_common.polygon_set.PolygonSet`` (the referee's distance), curvature as the
circumradius of consecutive reference points (Heron's formula here), speed from position
differences, analytic fillet geometry, and RRT^X paths from the planner core.
"""

import json
import math
import pathlib

import numpy as np
import pytest
import yaml

from rrtq_bringup.forest import forest_yaml
from rrtq_common.geometry import polygon_from_circle
from rrtq_common.polygon_set import PolygonSet
from rrtq_planner import routes
from rrtq_planner.guidance import (CurveStatus, FilletedPath, GuidanceConfig, GuidanceTrack,
                                   bump_weights, sample_in_time, speed_profile)
from rrtq_planner.shortcut import Shortener
from rrtq_testing.paths import OTTE, read_otte

CFG = GuidanceConfig(mode='gvf')
RADIUS = 0.5


def rrtx_path(polygons, start, goal, bounds, iterations, seed):
    """The RRT^X tree path, shortened as ``rrtq plan`` does, after a fixed iteration count."""
    planner = routes.make_planner(polygons, start, goal, bounds, RADIUS, seed)
    planner.run(iterations)
    return routes.shortest_route(planner, start, Shortener(polygons))


def curvature_and_speed(ref):
    """Circumradius curvature (Heron) and central-difference speed at interior samples."""
    p = ref.positions
    a = np.linalg.norm(p[1:-1] - p[:-2], axis=1)
    b = np.linalg.norm(p[2:] - p[1:-1], axis=1)
    c = np.linalg.norm(p[2:] - p[:-2], axis=1)
    s = 0.5 * (a + b + c)
    area = np.sqrt(np.maximum(s * (s - a) * (s - b) * (s - c), 0.0))
    with np.errstate(divide='ignore', invalid='ignore'):
        kappa = np.where(a * b * c > 0, 4.0 * area / (a * b * c), 0.0)
    return kappa, c / (2.0 * CFG.dt)


def full_reference(track, start):
    curve = track.roll(start)
    speeds = speed_profile(curve.points, CFG, 0.0, curve.status is CurveStatus.REACHED)
    return curve, sample_in_time(curve.points, speeds, CFG.dt, 20000)


def check_reference(curve, ref, grown, path_length):
    assert curve.status is CurveStatus.REACHED
    referee = PolygonSet(grown)
    clearance = min(referee.nearest(p)[0] for p in curve.points)
    assert clearance >= 0.0                  # never inside an augmented obstacle
    moving = np.hypot(*ref.velocities.T) > 0.0
    kappa, speed = curvature_and_speed(ref)
    inner = moving[1:-1]
    lateral = speed[inner] ** 2 * kappa[inner]
    assert np.mean(lateral <= CFG.a_max) >= 0.99
    # No stall: the goal is reached at a mean speed of at least half v_max, and the
    # reference ends at the goal.
    assert arrival(ref) <= path_length / (0.5 * CFG.v_max)
    assert np.allclose(ref.positions[-1], curve.points[-1])
    return clearance, float(np.mean(lateral <= CFG.a_max))


def test_fillet_matches_the_circle_tangent_to_both_legs():
    # An L: 10 m east, then 10 m north; r = 2 fits (tangent length 2 < 5).
    path = FilletedPath([[0, 0], [10, 0], [10, 10]], radius=2.0)
    assert path.length == pytest.approx(20.0 - 4.0 + math.pi, rel=1e-12)
    assert path.fillet_radii == pytest.approx([2.0])
    s = np.linspace(0.0, path.length, 101)
    for p, si in zip(path.point(s), s):
        q = path.query(p)
        assert abs(q.phi) < 1e-9 and q.s == pytest.approx(si, abs=1e-9)
    mid = path.point(8.0 + math.pi)            # the arc's midpoint, 45 degrees round
    assert np.hypot(*(mid - [8.0, 2.0])) == pytest.approx(2.0)
    inside = path.query(np.array([9.0, 1.0]))  # inside the turn = left of travel
    assert inside.phi > 0.0 and np.hypot(*inside.grad) == pytest.approx(1.0)
    # A leg too short for r: the fillet shrinks to half the shared leg.
    short = FilletedPath([[0, 0], [10, 0], [10, 1], [0, 1]], radius=2.0)
    assert short.fillet_radii == pytest.approx([0.5, 0.5])


def test_bump_weights_switch_between_the_boundaries():
    sigma = np.linspace(-0.5, 1.5, 201)
    w = bump_weights(sigma, 1.0)
    assert np.all(w[sigma <= 0.0] == 1.0) and np.all(w[sigma >= 1.0] == 0.0)
    assert np.all(np.diff(w) <= 0.0)
    assert bump_weights(np.array(0.5), 1.0) == pytest.approx(0.5)


@pytest.fixture(scope='module')
def otte():
    polygons = read_otte(OTTE / 'rand_Static.txt')
    start, goal = np.array([35.0, -40.0]), np.array([-40.0, 40.0])
    grown = routes.grow(polygons, RADIUS)
    bounds = routes.default_bounds(polygons, start, goal, RADIUS)
    return grown, rrtx_path(grown, start, goal, bounds, 1500, 3)


def test_reference_on_otte_rand_static(otte):
    grown, path = otte
    track = GuidanceTrack(path, grown, CFG)
    curve, ref = full_reference(track, path[0])
    check_reference(curve, ref, grown, routes.path_length(path))


def test_reference_in_a_forest():
    scenario = yaml.safe_load(forest_yaml(4, count=90, size=50.0))
    trees = [polygon_from_circle(o['circle']['center'], o['circle']['radius'], 16)
             for o in scenario['obstacles']]
    grown = routes.grow(trees, RADIUS)
    start, goal = np.array(scenario['start'], float), np.array(scenario['goal'], float)
    path = rrtx_path(grown, start, goal, (0.0, 50.0, 0.0, 50.0), 800, 1)
    track = GuidanceTrack(path, grown, CFG)
    curve, ref = full_reference(track, start)
    check_reference(curve, ref, grown, routes.path_length(path))


def occluded(virtual):
    """A straight path through a disc of radius 2 (the path known before the obstacle)."""
    disc = [polygon_from_circle((15.0, 0.4), 2.0, 32)]
    track = GuidanceTrack([[0.0, 0.0], [30.0, 0.0]], disc, CFG)
    if not virtual:
        track.field.virtual = []
    curve, ref = full_reference(track, np.zeros(2))
    return disc, curve, ref


def test_virtual_obstacle_takes_the_turn_earlier_and_gentler():
    disc, with_v, ref_v = occluded(True)
    _, without, ref_0 = occluded(False)
    for curve, ref in ((with_v, ref_v), (without, ref_0)):
        check_reference(curve, ref, disc, 30.0)
    kappa_v, _ = curvature_and_speed(ref_v)
    kappa_0, _ = curvature_and_speed(ref_0)
    assert kappa_v.max() < 0.5 * kappa_0.max()
    # Gentler turns let the speed profile keep more speed: the goal comes sooner.
    assert arrival(ref_v) < arrival(ref_0)


def arrival(ref):
    """Time (s) of the first sample at rest after the last moving one."""
    return ref.t[np.flatnonzero(np.hypot(*ref.velocities.T) > 0.0)[-1] + 1]


def test_walled_in_goal_is_reported_as_a_stall_not_a_hang():
    ring = [polygon_from_circle((20.0, 0.0), 3.0, 32)]
    cfg = GuidanceConfig(mode='gvf', stall_distance=15.0)
    track = GuidanceTrack([[0.0, 0.0], [20.0, 0.0]], ring, cfg)
    curve = track.roll(np.zeros(2))
    assert curve.status is CurveStatus.STALLED
    assert min(PolygonSet(ring).nearest(p)[0] for p in curve.points) >= 0.0


def test_reference_window_follows_the_robot():
    track = GuidanceTrack([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]], [], CFG)
    ref = track.reference([0.0, 0.0], [0.0, 0.0], t0=3.0)
    n = int(round(CFG.horizon / CFG.dt)) + 1
    assert ref.t == pytest.approx(3.0 + CFG.dt * np.arange(n))
    speed = np.hypot(*ref.velocities.T)
    assert speed[0] == 0.0 and speed.max() <= CFG.v_max + 1e-12
    assert np.all(np.diff(speed) <= CFG.a_max * CFG.dt + 1e-9)      # ramps up from rest
    later = track.reference([10.0, 0.3], [2.0, 0.0], t0=8.0)
    assert later.positions[0, 0] == pytest.approx(10.0, abs=CFG.step)
    assert np.hypot(*later.velocities[0]) == pytest.approx(2.0, rel=0.05)
    assert np.all(np.diff(later.positions[:, 0]) >= -1e-9)


@pytest.mark.parametrize('key, value', [('a_max', 0.0), ('v_max', -1.0),
                                        ('reactive_width', 0.05), ('step', float('nan'))])
def test_bad_config_names_the_field(key, value):
    with pytest.raises(ValueError, match=key if key != 'reactive_width' else 'repulsive'):
        GuidanceConfig(**{key: value})


def test_a_sink_of_the_composite_field_is_left_not_shuttled_in():
    # Recorded in the graph (data/guidance_sink.json): next to an obstacle the sense of
    # circulation chosen where the curve met it comes to oppose the path field, which
    # bends back; the composite field has a sink there (it points back at it from both
    # sides), the discrete curve shuttled between two points, and the rollout stalled.
    # The curve's own reversal flips that obstacle's sense once: it goes on to the goal.
    case = json.loads((pathlib.Path(__file__).parent / 'data' / 'guidance_sink.json')
                      .read_text())
    state = np.array(case['state'])
    obstacles = [np.array(p) for p in case['obstacles']]
    path = np.vstack((state[None, :2], case['plan']))
    track = GuidanceTrack(path, obstacles, CFG)
    for velocity in (None, state[2:]):
        curve = track.roll(state[:2], velocity)
        assert curve.status is CurveStatus.REACHED
        referee = PolygonSet(obstacles)
        assert min(referee.nearest(p)[0] for p in curve.points) > CFG.repulsive_offset
        steps = np.diff(curve.points[:-1], axis=0)          # the appended goal left out
        turn_back = np.einsum('ij,ij->i', steps[1:], steps[:-1]) < 0.0
        assert turn_back.sum() <= 1            # at most the one reversal that flips it
        # No detour: at most half as long again as the path.
        assert CFG.step * len(curve.points) <= 1.5 * track.path.length
