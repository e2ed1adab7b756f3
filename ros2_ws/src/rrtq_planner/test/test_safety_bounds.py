"""The bounds as an obstacle on the safety side: nearest and ahead, against shapely."""

import math

import numpy as np
import pytest
import shapely

from rrtq_common.lockstep import OnChange
from rrtq_planner.bounds import Region, wall_ahead, wall_distance
from rrtq_planner.safety import SafetyConfig, SafetyMonitor

BOUNDS = (-10.0, 10.0, -6.0, 6.0)
RECT = shapely.box(-10.0, -6.0, 10.0, 6.0)
BOX = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])


def monitor(radius=0.5, look_ahead=5.0):
    return SafetyMonitor(SafetyConfig(robot_radius=radius, look_ahead=look_ahead,
                                      bounds=BOUNDS))


def test_wall_distance_is_the_discs_distance_to_the_boundary_and_points_back_inside():
    """Against shapely: the centre's distance to the rectangle's boundary, less the radius,
    negative (by the distance to the rectangle) outside it; moving the centre a little
    along the direction takes it farther from the outside (inside) or nearer the
    rectangle (outside)."""
    rng = np.random.default_rng(1)
    for p in rng.uniform((-13.0, -9.0), (13.0, 9.0), (400, 2)):
        d, n = wall_distance(p, BOUNDS, 0.4)
        point = shapely.Point(p)
        inside = RECT.covers(point)
        exact = RECT.exterior.distance(point) if inside else -RECT.distance(point)
        assert d == pytest.approx(exact - 0.4, abs=1e-9)
        assert math.hypot(*n) == pytest.approx(1.0)
        moved = shapely.Point(p + 1e-3 * np.asarray(n))
        if inside:
            assert RECT.exterior.distance(moved) >= RECT.exterior.distance(point) - 1e-12
        else:
            assert RECT.distance(moved) < RECT.distance(point)


def test_wall_ahead_is_where_the_moving_disc_first_crosses_the_boundary():
    """Against shapely: the disc (radius 0.4) at the reported distance along the velocity
    reaches the boundary, slightly short of it not; nothing is reported when it would not
    reach it within the look-ahead or moves away; the normal is the inward one of the
    edge met."""
    rng = np.random.default_rng(2)
    inner = RECT.buffer(-0.4, join_style='mitre')

    def out_at(p, d, s):
        return not inner.covers(shapely.Point(p + s * d))
    hits = 0
    for _ in range(300):
        p = rng.uniform((-9.5, -5.5), (9.5, 5.5))
        v = rng.normal(size=2)
        d = v / np.linalg.norm(v)
        s, n = wall_ahead(p, v, BOUNDS, 0.4, 6.0)
        if math.isinf(s):
            assert not any(out_at(p, d, k) for k in np.linspace(0.0, 6.0, 601))
            continue
        hits += 1
        assert out_at(p, d, s + 1e-6) and not out_at(p, d, max(s - 1e-3, 0.0))
        assert float(np.dot(n, d)) < 0.0 and sorted(np.abs(n)) == [0.0, 1.0]
    assert hits > 100
    assert wall_ahead([9.0, 0.0], [-1.0, 0.0], BOUNDS, 0.4, 5.0) == (math.inf, (0.0, 0.0))
    assert wall_ahead([9.0, 0.0], [0.0, 0.0], BOUNDS, 0.4, 5.0) == (math.inf, (0.0, 0.0))
    # Already across an edge it heads further into: 0, and that edge's inward normal.
    assert wall_ahead([9.8, 0.0], [1.0, 0.3], BOUNDS, 0.4, 5.0) == (0.0, (-1.0, 0.0))


def test_the_monitor_reports_the_boundary_as_the_nearest_obstacle_when_it_is_nearer():
    """A robot (radius 0.5) 1.1 m from the east edge and 3 m from a detected box: the
    boundary is the nearest obstacle, 0.6 m off, pointing back inside; with the box nearer
    it is the box; out of the bounds, the way back in."""
    detected = OnChange(1, lambda: [('box', BOX + [5.0, 0.0])])
    east = monitor().step(0, [8.9, 0.5], detected, None)
    assert east.obstacle_distance == pytest.approx(0.6)
    assert east.obstacle_direction == (-1.0, 0.0)
    near_box = monitor().step(0, [4.0, 0.5], detected, None)
    assert near_box.obstacle_distance == pytest.approx(0.5)
    assert near_box.obstacle_direction == pytest.approx((-1.0, 0.0))
    south = monitor().step(0, [0.0, -5.3], None, None)
    assert south.obstacle_distance == pytest.approx(0.2) and south.obstacle_direction == (0.0, 1.0)
    blown = monitor().step(0, [13.0, 10.0], None, None)
    assert blown.obstacle_distance == pytest.approx(-5.5)
    assert blown.obstacle_direction == pytest.approx((-0.6, -0.8))
    # Without bounds (a core used alone): as before, nothing.
    alone = SafetyMonitor(SafetyConfig(robot_radius=0.5)).step(0, [8.9, 0.5], None, None)
    assert math.isinf(alone.obstacle_distance)


def test_the_monitor_reports_the_boundary_ahead_when_the_robot_heads_for_it():
    """Heading east 3 m short of the edge (less the radius) with a box 1 m off to the side:
    the boundary is the obstacle ahead; heading at the box, the box is; heading away from
    both, nothing."""
    detected = OnChange(1, lambda: [('box', BOX + [2.0, 2.0])])
    east = monitor().step(0, [6.5, 0.0], detected, None, velocity=[0.8, 0.0])
    assert east.ahead_distance == pytest.approx(3.0) and east.ahead_direction == (-1.0, 0.0)
    box = monitor().step(0, [3.0, -2.0], detected, None, velocity=[0.0, 1.0])
    assert box.ahead_distance == pytest.approx(3.5) and box.ahead_direction == pytest.approx(
        (0.0, -1.0))
    away = monitor().step(0, [6.5, 0.0], detected, None, velocity=[-0.1, 0.0])
    assert math.isinf(away.ahead_distance)
    # Obliquely: the distance along the velocity, s = gap / cos.
    oblique = monitor().step(0, [6.5, 0.0], detected, None, velocity=[1.0, 1.0])
    assert oblique.ahead_distance == pytest.approx(3.0 * math.sqrt(2.0))


def test_region_is_the_bounds_shrunk_by_the_margin():
    region = Region(BOUNDS, 1.5)
    assert np.array_equal(region.lo, [-8.5, -4.5]) and np.array_equal(region.hi, [8.5, 4.5])
    assert region.contains([[-8.5, 4.5], [0.0, 4.6], [9.0, 0.0]]).tolist() == [True, False, False]
    assert np.array_equal(region.clamp([12.0, -1.0]), [8.5, -1.0])
    # A margin wider than half an axis leaves its middle line.
    assert np.array_equal(Region(BOUNDS, 7.0).lo, [-3.0, 0.0])
