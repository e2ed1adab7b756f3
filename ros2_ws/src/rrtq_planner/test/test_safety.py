"""Safety core: D_rob against geometry done by hand, the augmentation against exact distances."""

import math

import numpy as np
import pytest
import shapely

from rrtq_common.geometry import kinodynamic_distance, ray_distance, segment_distance
from rrtq_planner.safety import SafetyConfig, SafetyMonitor, augment, clearance

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])


def test_ray_distance_matches_shapely_and_bounds_d_rob():
    """The distance from the ray from a leg's start through its target, against shapely's
    distance to that ray cut 1e4 m out: never below D_rob, equal to it abreast of the
    segment or past the target, the distance from the start behind it."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        a, b, p = rng.uniform(-5, 5, (3, 2))
        far = a + 1e4 * (b - a) / np.linalg.norm(b - a)
        exact = shapely.LineString([a, far]).distance(shapely.Point(p))
        assert ray_distance(a, b, p) == pytest.approx(exact, abs=1e-9)
        assert ray_distance(a, b, p) >= kinodynamic_distance(a, b, p) - 1e-12
    assert ray_distance([0, 0], [10, 0], [3, 0.7]) == pytest.approx(0.7)      # abreast
    assert ray_distance([0, 0], [10, 0], [14, -0.5]) == pytest.approx(0.5)    # past the target
    assert ray_distance([0, 0], [10, 0], [-1.5, 0.0]) == pytest.approx(1.5)   # behind
    assert ray_distance([2, 2], [2, 2], [5, 6]) == pytest.approx(5.0)         # a point


def test_segment_distance_matches_shapely():
    """The distance from a leg's segment (a short leg's, holding station) against shapely's."""
    rng = np.random.default_rng(4)
    for _ in range(200):
        a, b, p = rng.uniform(-5, 5, (3, 2))
        exact = shapely.LineString([a, b]).distance(shapely.Point(p))
        assert segment_distance(a, b, p) == pytest.approx(exact, abs=1e-9)
        assert segment_distance(a, b, p) >= ray_distance(a, b, p) - 1e-12
    assert segment_distance([0, 0], [10, 0], [14, -3.0]) == pytest.approx(5.0)  # past the target
    assert segment_distance([2, 2], [2, 2], [5, 6]) == pytest.approx(5.0)       # a point


def test_kinodynamic_distance_is_the_distance_to_the_leg_line():
    # Leg from (0, 0) to (10, 0): the deviation is |y|, wherever along the line.
    assert kinodynamic_distance([0, 0], [10, 0], [3, 0.7]) == pytest.approx(0.7)
    assert kinodynamic_distance([0, 0], [10, 0], [-4, -1.5]) == pytest.approx(1.5)
    # A diagonal leg: the distance of (1, 0) from y = x is 1/sqrt(2).
    assert kinodynamic_distance([0, 0, 5, 5], [4, 4, 0, 0], [1, 0, 9, 9]) == pytest.approx(
        1 / math.sqrt(2))
    # On the line: zero. Degenerate leg: distance from the target.
    assert kinodynamic_distance([1, 1], [4, 5], [2.5, 3.0]) == pytest.approx(0.0, abs=1e-12)
    assert kinodynamic_distance([2, 2], [2, 2], [5, 6]) == pytest.approx(5.0)
    # Leg from (-4, 0) to the origin, robot at (-2, 0.5): 0.5 m off the edge.
    assert kinodynamic_distance([-4, 0, 0, 0], [0, 0, 0, 0], [-2, 0.5, 0, 0]) == pytest.approx(0.5)


@pytest.mark.parametrize('margin', [0.1, 0.5, 2.0])
def test_augment_contains_the_minkowski_sum_and_is_tight(margin):
    grown = shapely.Polygon(augment(SQUARE, margin))
    original = shapely.Polygon(SQUARE)
    # Every point at distance <= margin of the obstacle is inside (sampled on the exact
    # boundary of the Minkowski sum: points at distance exactly `margin`).
    rng = np.random.default_rng(0)
    for angle in rng.uniform(0, 2 * math.pi, 400):
        direction = np.array([math.cos(angle), math.sin(angle)])
        # Walk out from the centre until the exact distance to the square is `margin`.
        lo, hi = 0.0, 10.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if original.distance(shapely.Point(np.array([1.0, 0.5]) + mid * direction)) < margin:
                lo = mid
            else:
                hi = mid
        point = shapely.Point(np.array([1.0, 0.5]) + lo * direction)
        assert grown.covers(point)
    # ... and nothing much more: the Hausdorff distance to the exact sum is below 1 %.
    exact = original.buffer(margin, quad_segs=256)
    assert grown.hausdorff_distance(exact) < 0.01 * margin + 1e-9


def test_margin_zero_returns_the_obstacle():
    assert np.array_equal(augment(SQUARE, 0.0), SQUARE)


def test_monitor_keeps_the_running_maximum_and_republishes_on_growth():
    monitor = SafetyMonitor(SafetyConfig(robot_radius=0.5, growth_threshold=0.1))
    assert monitor.update([0, 0], [10, 0], [1, 0.2])            # nothing published yet
    assert monitor.augmented([('a', SQUARE)])[0][0] == 'a'
    assert monitor.margin == pytest.approx(0.7)
    assert not monitor.update([0, 0], [10, 0], [2, 0.25])       # grew by 0.05 < 0.1
    assert monitor.update([0, 0], [10, 0], [3, 0.31])           # grew by 0.11
    assert monitor.update([0, 0], [10, 0], [3.5, 0.3])          # still owed a publication
    monitor.augmented([('a', SQUARE)])
    assert not monitor.update([0, 0], [10, 0], [4, 0.0])        # back on the line
    assert monitor.d_rob == 0.0 and monitor.d_rob_max == pytest.approx(0.31)


def test_clearance_signed_and_nearest():
    far = SQUARE + np.array([10.0, 0.0])
    value, index = clearance([3.0, 0.5], [far, SQUARE], robot_radius=0.25)
    assert index == 1 and value == pytest.approx(0.75)
    inside, _ = clearance([1.0, 0.4], [SQUARE], robot_radius=0.0)
    assert inside == pytest.approx(-0.4)
    assert clearance([0, 0], [], 1.0) == (math.inf, -1)


def test_augmentation_never_swallows_the_robot():
    monitor = SafetyMonitor(SafetyConfig(robot_radius=0.5))
    monitor.update([0, 0], [10, 0], [1, 1.0])                   # D_rob = 1: margin 1.5
    robot = np.array([1.0, 1.6])                                # 0.6 m above the square
    (_, near), = monitor.augmented([('a', SQUARE)], robot)
    (_, free), = monitor.augmented([('b', SQUARE + [20.0, 0.0])], robot)
    assert not shapely.Polygon(near).covers(shapely.Point(robot))
    assert shapely.Polygon(near).distance(shapely.Point(robot)) == pytest.approx(0.05, abs=0.01)
    assert shapely.Polygon(free).hausdorff_distance(
        shapely.Polygon(augment(SQUARE + [20.0, 0.0], 1.5))) < 1e-9   # far ones: full margin


def test_nearest_detected_obstacle_distance_and_direction_match_shapely():
    """What the controller's keep-off acts on: the robot disc's distance to the nearest
    detected polygon and the unit vector from its nearest point to the robot."""
    from rrtq_common.polygon_set import PolygonSet
    from rrtq_planner.safety import nearest_obstacle
    polys = [SQUARE, SQUARE + [5.0, 0.0], np.array([[0.0, 4.0], [2.0, 6.0], [-1.0, 6.0]])]
    shapes = PolygonSet(polys)
    rng = np.random.default_rng(5)
    for p in rng.uniform(-3, 8, (200, 2)):
        d, n = nearest_obstacle(p, shapes, polys, 0.2)
        exact = min(shapely.Polygon(q).distance(shapely.Point(p)) for q in polys)
        if exact == 0.0:
            assert d <= -0.2 + 1e-9 and n == (0.0, 0.0)
            continue
        assert d == pytest.approx(exact - 0.2, abs=1e-9)
        foot = np.asarray(p) - (exact * np.asarray(n))       # back along n: on the obstacle
        assert min(shapely.Polygon(q).exterior.distance(shapely.Point(foot)) for q in polys) < 1e-9
    assert nearest_obstacle([0.0, 0.0], PolygonSet([]), [], 0.2) == (math.inf, (0.0, 0.0))


def test_the_obstacle_ahead_along_the_velocity_is_the_one_the_disc_would_meet():
    """The case the nearest obstacle misses: a robot sliding south along one obstacle's west
    face toward a second one below. The nearest is the face beside it; the one ahead is
    the second, at the distance the disc (radius 0.2) travels before it touches it, as
    shapely's swept disc finds by bisection."""
    from rrtq_common.lockstep import OnChange
    beside = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 6.0], [0.0, 6.0]])
    below = np.array([[-3.0, -3.0], [1.0, -3.0], [1.0, -1.0], [-3.0, -1.0]])
    monitor = SafetyMonitor(SafetyConfig(robot_radius=0.2))
    robot, velocity = np.array([-0.5, 3.0]), np.array([0.0, -1.2])
    step = monitor.step(0, robot, OnChange(1, lambda: [('beside', beside), ('below', below)]),
                        None, velocity=velocity)
    assert step.obstacle_distance == pytest.approx(0.3) and step.obstacle_direction == (-1.0, 0.0)
    assert step.ahead_distance == pytest.approx(3.8, abs=0.01)     # 3 m to y = -1, less 0.2
    assert step.ahead_direction == pytest.approx((0.0, 1.0))        # the lower one's top face
    # Against shapely: the disc at the reported distance touches, slightly short of it not.
    shapes = [shapely.Polygon(beside), shapely.Polygon(below)]

    def touches(p, d, s):
        return any(shapely.Point(p + s * d).buffer(0.2, 256).intersects(q) for q in shapes)
    rng = np.random.default_rng(6)
    hits = 0
    for _ in range(100):
        p, v = rng.uniform(-4.0, 4.0, 2), rng.normal(size=2)
        if any(q.distance(shapely.Point(p)) <= 0.2 for q in shapes):
            continue
        s = SafetyMonitor(SafetyConfig(robot_radius=0.2, look_ahead=20.0)).step(
            0, p, OnChange(1, lambda: [('beside', beside), ('below', below)]), None,
            velocity=v).ahead_distance
        d = v / np.linalg.norm(v)
        if math.isinf(s):
            assert not any(touches(p, d, k) for k in np.linspace(0.0, 20.0, 401))
            continue
        hits += 1
        assert touches(p, d, s + 0.01) and not touches(p, d, s * 0.995 - 1e-3)
    assert hits > 20
    # At rest, or with the look-ahead off: nothing ahead.
    still = SafetyMonitor(SafetyConfig(robot_radius=0.2)).step(
        0, [-0.5, 3.0], OnChange(1, lambda: [('below', below)]), None, velocity=[0.0, 0.0])
    assert math.isinf(still.ahead_distance) and still.ahead_direction == (0.0, 0.0)
    off = SafetyMonitor(SafetyConfig(robot_radius=0.2, look_ahead=0.0)).step(
        0, [-0.5, 3.0], OnChange(1, lambda: [('below', below)]), None, velocity=[0.0, -1.0])
    assert math.isinf(off.ahead_distance)


def test_a_growing_map_grows_only_its_new_obstacles_and_publishes_what_growing_afresh_gives():
    """The monitor reuses an obstacle grown at the last publication when its id, radius and
    vertices are the same (GrownCache); each published ring is the one grown afresh."""
    from rrtq_common.lockstep import OnChange
    from rrtq_planner.safety import grow_polygon
    rng = np.random.default_rng(5)
    boxes = [(f'b{i}', SQUARE + rng.uniform(-30, 30, 2)) for i in range(12)]
    monitor = SafetyMonitor(SafetyConfig(robot_radius=0.4))
    far = np.array([100.0, 100.0])                       # no obstacle near enough to clip
    published = []
    for k, count in enumerate((4, 4, 7, 12)):           # the map grows; once it does not
        out = monitor.step(k, far, OnChange(k + 1, lambda n=count: boxes[:n]), None)
        published.append(out.augmented)
        for (oid, ring), (bid, box) in zip(out.augmented, boxes[:count], strict=True):
            assert oid == bid and np.array_equal(ring, grow_polygon(box, 0.4))
    # swept and augmented, 12 obstacles each: grown once, however often the set changed
    assert monitor.grown == 24
    moved = [(oid, box + [0.5, 0.0]) if oid == 'b3' else (oid, box) for oid, box in boxes]
    out = monitor.step(9, far, OnChange(20, lambda: moved), None)
    assert monitor.grown == 26                          # b3 moved: grown again, twice
    assert np.array_equal(dict(out.augmented)['b3'], grow_polygon(moved[3][1], 0.4))
    monitor.update([0, 0], [10, 0], [1, 1.0])           # the margin grows: every one afresh
    out = monitor.step(10, far, OnChange(21, lambda: moved), None)
    assert monitor.grown == 38                          # (the robot radius's: reused)
    assert all(np.array_equal(ring, grow_polygon(box, 1.4))
               for (_, ring), (_, box) in zip(out.augmented, moved, strict=True))


def test_clearance_and_collision_are_against_the_robots_map_not_the_truth():
    """The monitor is built from its settings alone (no truth): the clearance, the nearest
    obstacle and the collision flag of a step are those of the detected obstacles where the
    odometry puts the robot, against shapely's distances. An obstacle the robot has not
    detected does not count; one it believes in does."""
    import inspect

    from rrtq_common.lockstep import OnChange
    assert list(inspect.signature(SafetyMonitor).parameters) == ['config']
    monitor = SafetyMonitor(SafetyConfig(robot_radius=0.3))
    nothing = monitor.step(0, [5.0, 5.0], OnChange(1, lambda: []), None)
    assert math.isinf(nothing.clearance) and nothing.nearest == '' and not nothing.collision
    far_box = SQUARE + [10.0, 0.0]
    believed = [('near', SQUARE), ('far', far_box)]
    rng = np.random.default_rng(9)
    for k, p in enumerate(rng.uniform(-3.0, 13.0, (30, 2))):
        gaps = [shapely.Polygon(poly).distance(shapely.Point(p)) for _, poly in believed]
        if min(gaps) <= 0.3:
            continue
        step = monitor.step(k + 1, p, OnChange(2, lambda: believed), None)
        assert step.clearance == pytest.approx(min(gaps) - 0.3, abs=1e-9)
        assert step.clearance == step.obstacle_distance
        assert step.nearest == believed[int(np.argmin(gaps))][0]
        assert not step.collision
    # The odometry puts the disc onto the believed square: a collision, latched.
    onto = monitor.step(100, [-0.1, 0.5], OnChange(2, lambda: believed), None)
    assert onto.collision and onto.new_collision and onto.nearest == 'near'
    assert onto.clearance == pytest.approx(-0.2)
    later = monitor.step(101, [-5.0, 0.5], OnChange(2, lambda: believed), None)
    assert later.collision and not later.new_collision
