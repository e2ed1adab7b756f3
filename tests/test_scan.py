"""Perception from a laser scan: the ray caster, the obstacle mapper, the scenario section."""

import math

import numpy as np
import pytest
import shapely

from rrtq_common.scan import PerceptionConfig, beam_angles, beam_directions, period_steps
from rrtq_common.world import ObstacleSpec
from rrtq_planner.obstacle_map import MapEvent, MapperConfig, ObstacleMap, segment
from rrtq_sim.mujoco_model import BaseParameters
from rrtq_sim.mujoco_rays import MujocoRays
from rrtq_sim.scan import LaserScanner, cast_rays, polygon_rays

SQUARE = np.array([[2.0, -1.0], [4.0, -1.0], [4.0, 1.0], [2.0, 1.0]])


def _returns(position, ranges):
    hit = np.isfinite(ranges)
    return np.asarray(position, float) + ranges[hit, None] * beam_directions(len(ranges))[hit]


# -- ray caster ---------------------------------------------------------------------------

def test_ranges_equal_the_analytic_distance_to_a_square():
    beams = 720
    ranges = cast_rays([0.0, 0.0], beam_directions(beams), [SQUARE], 10.0)
    angles = beam_angles(beams)
    # The near face x = 2 is seen for |θ| <= atan(1/2); its range is 2 / cos θ.
    near = np.abs(angles) < math.atan2(1.0, 2.0) - 1e-9
    np.testing.assert_allclose(ranges[near], 2.0 / np.cos(angles[near]), rtol=0, atol=1e-12)
    # The side faces y = ±1 are seen between atan(1/4) and atan(1/2): range 1 / |sin θ|.
    side = (np.abs(angles) > math.atan2(1.0, 2.0) + 1e-9) & (np.abs(angles) < math.atan2(1.0, 4.0))
    assert not side.any()  # from the origin the sides are edge-on: none to see
    # Every beam outside the square's angular extent misses: inf, not range_max.
    miss = np.abs(angles) > math.atan2(1.0, 2.0) + 1e-9
    assert np.all(np.isinf(ranges[miss]))
    assert np.count_nonzero(np.isfinite(ranges)) == np.count_nonzero(~miss)


def test_side_faces_and_range_limit():
    directions = beam_directions(360)
    origin = np.array([3.0, -4.0])        # below the square: sees its bottom face y = -1
    ranges = cast_rays(origin, directions, [SQUARE], 10.0)
    angles = beam_angles(360)
    up = np.isfinite(ranges)
    np.testing.assert_allclose(ranges[up], 3.0 / np.sin(angles[up]), atol=1e-12)
    points = _returns(origin, ranges)
    np.testing.assert_allclose(points[:, 1], -1.0, atol=1e-12)
    assert np.all((points[:, 0] >= 2.0 - 1e-12) & (points[:, 0] <= 4.0 + 1e-12))
    # Out of range: nothing at all, every beam inf.
    assert np.all(np.isinf(cast_rays(origin, directions, [SQUARE], 2.9)))


def test_seeded_noise_repeats_and_has_its_sigma():
    config = PerceptionConfig(beams=360, range_max=10.0, noise_std=0.05)
    scans = [LaserScanner(config, np.random.default_rng(seed)).scan([0.0, 0.0], [ObstacleSpec('square', SQUARE)])
             for seed in (3, 3, 4)]
    np.testing.assert_array_equal(scans[0], scans[1])
    assert not np.array_equal(scans[0], scans[2])
    exact = cast_rays([0.0, 0.0], beam_directions(360), [SQUARE], 10.0)
    np.testing.assert_array_equal(np.isfinite(scans[0]), np.isfinite(exact))
    # Many scans: the error's spread is the configured sigma.
    scanner = LaserScanner(config, np.random.default_rng(0))
    finite = np.isfinite(exact)
    errors = np.concatenate([scanner.scan([0.0, 0.0], [ObstacleSpec('square', SQUARE)])[finite] - exact[finite]
                             for _ in range(200)])
    assert abs(errors.std() - 0.05) < 0.005 and abs(errors.mean()) < 0.005


# An L (non-convex: MuJoCo holds it as the prisms of its triangles) and a disc.
L_SHAPE = np.array([[-5.0, -5.0], [-2.0, -5.0], [-2.0, -4.0], [-4.0, -4.0], [-4.0, -2.0],
                    [-5.0, -2.0]])
DISC = np.array([[1.0 + 0.8 * math.cos(a), 4.0 + 0.8 * math.sin(a)]
                 for a in np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)])
WORLD = [ObstacleSpec('square', SQUARE), ObstacleSpec('l', L_SHAPE), ObstacleSpec('disc', DISC)]


@pytest.mark.parametrize('origin', [(0.0, 0.0), (-3.0, -3.0), (3.0, 3.5), (-1.5, 2.0)])
def test_mujoco_rays_equal_the_polygon_caster(origin):
    """mj_multiRay in the plant's model against the analytic caster: the same beams hit,
    at the same ranges but for MuJoCo's single-precision mesh vertices; the robot's own
    cylinder (0.4 m, the origin inside it) is never seen."""
    rays = MujocoRays(WORLD, BaseParameters(40.0, 45.0, 0.0, 0.4))
    directions = beam_directions(720)
    # A beam through a vertex (within 1e-6 rad) may graze either way: those are left out.
    vertices = np.concatenate([spec.polygon for spec in WORLD]) - np.asarray(origin)
    towards = np.arctan2(vertices[:, 1], vertices[:, 0])
    gap = np.angle(np.exp(1j * (beam_angles(720)[:, None] - towards[None, :])))
    clear = np.abs(gap).min(axis=1) > 1e-6
    for range_max in (3.0, 12.0):
        ours = rays(origin, directions, WORLD, range_max)
        reference = polygon_rays(origin, directions, WORLD, range_max)
        hit = np.isfinite(reference) & clear
        assert hit.any()
        np.testing.assert_array_equal(np.isfinite(ours)[clear], hit[clear])
        np.testing.assert_allclose(ours[hit], reference[hit], rtol=0.0, atol=1e-6)
        assert np.all(ours[hit] > 0.4)


def test_mujoco_rays_see_only_the_obstacles_that_exist():
    rays = MujocoRays(WORLD, BaseParameters(40.0, 45.0, 0.0, 0.4))
    directions = beam_directions(360)
    present = [WORLD[1], WORLD[2]]
    np.testing.assert_allclose(rays((0.0, 0.0), directions, present, 12.0),
                               polygon_rays((0.0, 0.0), directions, present, 12.0), atol=1e-6)
    assert np.all(np.isinf(rays((0.0, 0.0), directions, [], 12.0)))
    # Back again: the square is seen once it exists.
    again = rays((0.0, 0.0), directions, WORLD, 12.0)
    np.testing.assert_allclose(again, polygon_rays((0.0, 0.0), directions, WORLD, 12.0),
                               atol=1e-6)


def test_mujoco_rays_see_a_users_own_walls_but_not_its_robot(tmp_path):
    """A user's MJCF: a wall of the file is seen (it is part of the physical world), the
    robot's parts below its base body are not."""
    mjcf = tmp_path / 'robot.xml'
    mjcf.write_text("""<mujoco>
  <option gravity="0 0 0"/>
  <worldbody>
    <geom name="wall" type="box" pos="0 -6 0" size="10 0.5 1"/>
    <body name="base" pos="0 0 0.1">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <geom type="cylinder" size="0.3 0.1" mass="20"/>
      <body name="bumper" pos="0.5 0 0"><geom type="box" size="0.1 0.3 0.05" mass="1"/></body>
    </body>
  </worldbody>
  <actuator><motor name="fx" joint="x"/><motor name="fy" joint="y"/></actuator>
</mujoco>""")
    rays = MujocoRays([], mjcf=str(mjcf))
    directions = np.array([[1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
    ranges = rays((0.0, 0.0), directions, [], 10.0)
    assert np.isinf(ranges[0])                       # the bumper is the robot's own
    assert ranges[1] == pytest.approx(5.5, abs=1e-9)  # the wall's face at y = -5.5
    assert np.isinf(ranges[2])
    # Moved 2 m toward the wall: the base's position is where the rays start.
    assert rays((0.0, -2.0), directions, [], 10.0)[1] == pytest.approx(3.5, abs=1e-9)


def test_scan_period_must_be_whole_steps():
    assert period_steps(10.0, 0.05) == 2
    assert period_steps(20.0, 0.05) == 1
    with pytest.raises(ValueError, match='whole number'):
        period_steps(30.0, 0.05)
    with pytest.raises(ValueError, match='whole number'):
        period_steps(7.0, 0.05)


# -- mapper -------------------------------------------------------------------------------

def _scan(position, polygons, config, rng=None):
    ranges = cast_rays(position, beam_directions(config.beams), polygons, config.range_max)
    if rng is not None and config.noise_std > 0:
        finite = np.isfinite(ranges)
        ranges[finite] += rng.normal(0.0, config.noise_std, finite.sum())
    return ranges


def _covers(points, polygon, tol=1e-9):
    shape = shapely.Polygon(polygon).buffer(tol)
    return bool(np.all(shapely.intersects_xy(shape, points[:, 0], points[:, 1])))


@pytest.mark.parametrize('noise', [0.0, 0.02])
def test_every_return_lies_in_a_published_polygon(noise):
    config = MapperConfig(beams=360, range_max=8.0, noise_std=noise)
    triangle = np.array([[-3.0, 2.0], [-1.0, 2.5], [-2.0, 4.0]])
    circle = np.array([[5 + math.cos(a), -3 + math.sin(a)] for a in np.linspace(0, 2 * math.pi, 24,
                                                                                 endpoint=False)])
    truth = [SQUARE, triangle, circle]
    mapper = ObstacleMap(config)
    rng = np.random.default_rng(1)
    seen = []
    for position in ([0.0, 0.0], [0.5, -2.0], [-1.0, 0.5]):
        ranges = _scan(position, truth, config, rng)
        mapper.integrate(position, ranges)
        seen.append(_returns(position, ranges))
    polygons = [o.polygon for o in mapper.obstacles]
    assert len(polygons) == 3  # one per true obstacle, none split, none merged
    for points in seen:
        for p in points:
            assert any(_covers(p[None], poly) for poly in polygons), p
    for poly in polygons:  # published polygons are convex and counter-clockwise
        shape = shapely.Polygon(poly)
        assert shape.is_valid and shape.exterior.is_ccw
        assert abs(shape.convex_hull.area - shape.area) < 1e-9


def test_an_obstacle_seen_from_two_poses_grows_and_keeps_its_id():
    config = MapperConfig(beams=360, range_max=8.0, noise_std=0.01)
    mapper = ObstacleMap(config)
    rng = np.random.default_rng(2)
    first = _scan([0.0, 0.0], [SQUARE], config, rng)
    update = mapper.integrate([0.0, 0.0], first)
    assert update.events == [(MapEvent.DETECTED, 'scan_1')]
    area_before = shapely.Polygon(mapper.obstacles[0].polygon).area
    second = _scan([3.0, 4.0], [SQUARE], config, rng)      # the top face: unseen so far
    update = mapper.integrate([3.0, 4.0], second)
    assert update.events == [(MapEvent.GROWN, 'scan_1')]
    assert [o.id for o in mapper.obstacles] == ['scan_1']
    polygon = mapper.obstacles[0].polygon
    assert shapely.Polygon(polygon).area > area_before + 1.0
    assert _covers(_returns([0.0, 0.0], first), polygon)
    assert _covers(_returns([3.0, 4.0], second), polygon)
    # The hull of both faces covers most of the true square (its far corner (4, -1) unseen).
    assert shapely.Polygon(polygon).intersection(shapely.Polygon(SQUARE)).area > 0.5 * 4.0
    # Seeing the same faces again changes nothing (no republishing on noise).
    assert mapper.integrate([0.0, 0.0], _scan([0.0, 0.0], [SQUARE], config, rng)).events == []


def test_freed_space_removes_the_obstacle_and_only_it():
    config = MapperConfig(beams=360, range_max=8.0, noise_std=0.01)
    mapper = ObstacleMap(config)
    rng = np.random.default_rng(3)
    other = SQUARE + [-7.0, 0.0]
    mapper.integrate([0.0, 0.0], _scan([0.0, 0.0], [SQUARE, other], config, rng))
    assert len(mapper.obstacles) == 2
    ids = {o.id: o.polygon.mean(axis=0)[0] > 0 for o in mapper.obstacles}
    # The square vanishes from the truth: the scan passes through where it was.
    update = mapper.integrate([0.0, 0.0], _scan([0.0, 0.0], [other], config, rng))
    removed = [i for e, i in update.events if e is MapEvent.REMOVED]
    assert len(removed) == 1 and ids[removed[0]]
    assert [o.id for o in mapper.obstacles] == [i for i, right in ids.items() if not right]


def test_an_obstacle_still_seen_is_not_removed():
    config = MapperConfig(beams=360, range_max=8.0, noise_std=0.02)
    mapper = ObstacleMap(config)
    rng = np.random.default_rng(4)
    for position in ([0.0, 0.0], [0.0, 4.0], [6.0, 3.0], [6.0, -3.0], [1.0, -3.0]) * 4:
        update = mapper.integrate(position, _scan(position, [SQUARE], config, rng))
        assert all(e is not MapEvent.REMOVED for e, _ in update.events)
    assert len(mapper.obstacles) == 1


def test_seeing_through_a_gap_an_obstacle_spans_keeps_it():
    # Two boxes 0.1 m apart seen from 6 m: their clusters' polygons overlap, one obstacle
    # spans the gap. Seen from 1 m, beams pass through the gap and through its core, but
    # the boxes' own returns land in it: it stays, under its id.
    config = MapperConfig(beams=360, range_max=8.0, noise_std=0.01)
    left = np.array([[0.0, 6.0], [1.0, 6.0], [1.0, 7.0], [0.0, 7.0]])
    right = left + [1.1, 0.0]
    mapper = ObstacleMap(config)
    rng = np.random.default_rng(5)
    mapper.integrate([1.0, 0.0], _scan([1.0, 0.0], [left, right], config, rng))
    assert [o.id for o in mapper.obstacles] == ['scan_1']
    ranges = _scan([1.05, 5.0], [left, right], config, rng)
    through = np.isinf(ranges) & (np.abs(beam_angles(360) - math.pi / 2) < 0.1)
    assert through.sum() >= config.free_beams
    update = mapper.integrate([1.05, 5.0], ranges)
    assert all(e is not MapEvent.REMOVED for e, _ in update.events)
    assert 'scan_1' in [o.id for o in mapper.obstacles]


def test_segmentation_breaks_on_range_jumps():
    config = MapperConfig(beams=360, range_max=20.0)
    near = np.array([[2.0, -0.5], [3.0, -0.5], [3.0, 0.5], [2.0, 0.5]])
    far = np.array([[6.0, 0.6], [7.0, 0.6], [7.0, 2.0], [6.0, 2.0]])  # behind, beside near
    ranges = cast_rays([0.0, 0.0], beam_directions(360), [near, far], 20.0)
    points = np.zeros((360, 2)) + np.where(np.isfinite(ranges), ranges, 0)[:, None] * \
        beam_directions(360)
    clusters = segment(points, ranges, config)
    assert len(clusters) == 2
    # A wall all around: one cluster, wrapped.
    box = np.array([[-5.0, -5.0], [5.0, -5.0], [5.0, 5.0], [-5.0, 5.0]])
    ranges = cast_rays([0.0, 0.0], beam_directions(360), [box], 20.0)
    points = ranges[:, None] * beam_directions(360)
    assert [len(c) for c in segment(points, ranges, config)] == [360]


# -- scenario -----------------------------------------------------------------------------

def test_the_example_scenario_loads_with_its_perception(root):
    from rrtq_bringup.scenario import load_scenario
    scenario = load_scenario(root / 'scenarios' / 'scan_perception.yaml')
    assert scenario.perception == PerceptionConfig(source='scan', beams=360, range_max=8.0,
                                                   rate=10.0, noise_std=0.02)
    default = load_scenario(root / 'scenarios' / 'defaults_only.yaml')
    assert default.perception.source == 'polygons'
    assert default.perception.range_max == default.perception_radius


@pytest.mark.parametrize('section, key, message', [
    ('{source: scan, beams: 0}', 'perception.beams', '>= 3'),
    ('{source: scan, beams: -4}', 'perception.beams', '>= 3'),
    ('{source: scan, beams: 90.5}', 'perception.beams', 'integer'),
    ('{source: lidar}', 'perception.source', 'polygons, scan'),
    ('{source: scan, range: 0}', 'perception.range', '> 0'),
    ('{source: scan, noise: -0.1}', 'perception.noise', '>= 0'),
    ('{source: scan, rate: 7.0}', 'perception.rate', 'whole number'),
    ('{source: scan, fov: 180}', 'perception.fov', ''),
], ids=['beams0', 'beams_negative', 'beams_fraction', 'source', 'range', 'noise', 'rate', 'unknown'])
def test_bad_perception_is_an_error_naming_file_and_key(tmp_path, section, key, message):
    from rrtq_bringup.scenario import load_scenario
    from rrtq_common.yaml_reader import ScenarioError
    path = tmp_path / 'bad.yaml'
    path.write_text('bounds: {x: [-5, 5], y: [-5, 5]}\nstart: [-4, -4]\ngoal: [4, 4]\n'
                    f'perception: {section}\n')
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.file == str(path)
    assert info.value.key == key
    assert message in info.value.message


# -- lock-step and graph ------------------------------------------------------------------

def test_a_requirement_every_k_steps_holds_only_those_steps():
    from rrtq_common.lockstep import Requirement, StepGate
    dt = 50_000_000
    steps = []
    gate = StepGate([Requirement('scan', every=2)], lockstep=True, dt_ns=dt,
                    on_step=steps.append)
    gate.add('odom', 0, 'o0')
    assert steps == []                      # step 0 carries a scan: it waits for it
    gate.add('scan', 0, 's0')
    gate.add('odom', dt, 'o1')              # step 1 carries none: it goes at once
    gate.add('odom', 2 * dt, 'o2')
    assert [(s.stamp_ns, s.get('scan')) for s in steps] == [(0, 's0'), (dt, None)]
    gate.add('scan', 2 * dt, 's2')
    assert [(s.stamp_ns, s.get('scan')) for s in steps][-1] == (2 * dt, 's2')


def _graph(tmp_path, perception):
    from rrtq_bringup.graph import build_graph
    from rrtq_bringup.scenario import load_scenario
    from rrtq_common import topics
    path = tmp_path / 'g.yaml'
    path.write_text('bounds: {x: [-5, 5], y: [-5, 5]}\nstart: [-4, -4]\ngoal: [4, 4]\n'
                    + (f'perception: {perception}\n' if perception else ''))
    return {s.name: s for s in build_graph(load_scenario(path), 0.0, str(tmp_path / 'r.mcap'))}, topics


def test_the_graph_starts_the_mapper_only_for_scans(tmp_path):
    polygons, topics = _graph(tmp_path, None)
    assert 'obstacle_mapper' not in polygons
    assert topics.PERCEPTION_STATUS in polygons['obstacle_spawner'].publishes
    assert set(polygons['obstacle_spawner'].params) == {'use_sim_time', 'scenario',
                                                        'ready_when_matched'}
    scan, _ = _graph(tmp_path, '{source: scan, beams: 90, range: 4.0, rate: 5.0, noise: 0.01}')
    mapper, spawner = scan['obstacle_mapper'], scan['obstacle_spawner']
    # the robot side: its odometry and its scans, no scenario file, no simulator truth
    assert set(mapper.subscribes) == {topics.CLOCK, topics.ODOM, topics.SCAN}
    assert 'scenario' not in mapper.params
    assert (mapper.params['beams'], mapper.params['range_max'], mapper.params['rate'],
            mapper.params['noise_std']) == (90, 4.0, 5.0, 0.01)
    assert mapper.publishes == (topics.PERCEPTION_STATUS,)
    assert topics.PERCEPTION_STATUS not in spawner.publishes and topics.SCAN in spawner.publishes
    assert topics.SCAN in scan['recorder'].subscribes


def test_the_physics_plants_scanner_casts_in_its_model(tmp_path):
    """With plant.model mujoco the spawner is told the plant's model and file, and builds
    MuJoCo's caster (mj_multiRay) rather than the polygon one."""
    from rrtq_bringup.graph import build_graph
    from rrtq_bringup.scenario import load_scenario
    path = tmp_path / 'm.yaml'
    path.write_text('bounds: {x: [-5, 5], y: [-5, 5]}\nstart: [-4, -4]\ngoal: [4, 4]\n'
                    'plant: {model: mujoco}\nperception: {source: scan}\n')
    spawner = {s.name: s for s in build_graph(load_scenario(path), 0.0,
                                               str(tmp_path / 'r.mcap'))}['obstacle_spawner']
    assert spawner.params['model'] == 'mujoco' and spawner.params.get('mjcf') in ('', None)
    linear, _ = _graph(tmp_path, '{source: scan}')
    assert 'model' not in linear['obstacle_spawner'].params


# -- closed loop --------------------------------------------------------------------------

LOOP = """
name: loop-scan
seed: 5
bounds: {x: [-10, 10], y: [-10, 10]}
start: [-6.0, -6.0]
goal: [6.0, 5.0]
duration: 90.0
perception_radius: 5.0
robot_radius: 0.3
perception: {source: scan, beams: 180, range: 5.0, rate: 10.0, noise: 0.01}
plant: {model: rover, stiffness: 0.0}
controller:
  variant: nominal
  M: 10.0
  R: 0.02
  initial_gain: [[40, 0, 30, 0], [0, 40, 0, 30]]
  probing_std: 5.0
planner: {steer_distance: 3.0, iterations_per_step: 20, max_nodes: 800}
obstacles:
  - {id: mid, polygon: [[-1, -3], [1, -3], [1, 3], [-1, 3]], appear_at: 2.0}
"""


def test_a_scan_run_reaches_its_goal_and_records_scans_and_map(tmp_path, root):
    import json
    import subprocess

    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import LaserScan

    from rrtq_bringup.report.run import summarise
    from rrtq_bringup.run_data import embedded_scenario, read_run
    path = tmp_path / 'loop_scan.yaml'
    path.write_text(LOOP)
    out = tmp_path / 'run'
    proc = subprocess.run([str(root / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert json.loads((out / 'summary.json').read_text())['outcome'] == 'goal_reached'
    data = read_run(out / 'run.mcap')
    judged = summarise(data, embedded_scenario(out / 'run.mcap'))
    assert judged['collided'] is False and judged['min_clearance_m'] > 0.0
    steps = data.topics['/perception/status']
    assert data.topics['/scan'] == (steps + 1) // 2           # 10 Hz at dt = 0.05 s
    # The robot's map is the mapper's (ids scan_<n>), never the spawner's true polygons,
    # and it saw the wall: some map obstacle overlaps it.
    ids = {oid for _, obstacles in data.detected for oid, _ in obstacles}
    assert ids and all(oid.startswith('scan_') for oid in ids)
    wall = shapely.Polygon([[-1, -3], [1, -3], [1, 3], [-1, 3]])
    assert any(shapely.Polygon(poly).intersects(wall)
               for _, obstacles in data.detected for _, poly in obstacles)
    with open(out / 'run.mcap', 'rb') as fh:
        first = next(m for _, _, m in make_reader(fh).iter_messages(topics=['/scan']))
    scan = deserialize_message(first.data, LaserScan)
    assert scan.header.frame_id == 'base_link' and len(scan.ranges) == 180
    assert scan.range_max == pytest.approx(5.0) and scan.angle_min == pytest.approx(-math.pi)
