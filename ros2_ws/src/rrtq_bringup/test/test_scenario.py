"""Scenario files: the contract's example (docs/design.md) loads, defaults apply, every bad input names its key."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from rrtq_bringup.scenario import (
    ScenarioError,
    build_disturbance,
    build_plant,
    load_scenario,
    parse_scenario,
)
from rrtq_common.world import TrueObstacles
from rrtq_controller.config import Variant as ControllerVariant
from rrtq_sim.disturbance import DisturbanceModel
from rrtq_sim.plant import PlantModel, SpringAnchor, rover_matrices

DATA = Path(__file__).parent / 'data'
BASE = {'bounds': {'x': [-10, 10], 'y': [-10, 10]}, 'start': [-8.0, -8.0], 'goal': [8.0, 8.0]}


def parse(**overrides):
    data = copy.deepcopy(BASE) | overrides
    return parse_scenario(data, str(DATA / 'inline.yaml'))


def test_full_example_loads():
    sc = load_scenario(DATA / 'full.yaml')
    assert (sc.name, sc.seed, sc.duration, sc.perception_radius, sc.robot_radius) == ('rrtqx-paper', 7, 300.0, 8.0, 0.5)
    assert sc.bounds == ((-20.0, 20.0), (-20.0, 20.0))
    np.testing.assert_array_equal(sc.start, [-15.0, -15.0])
    a, b = rover_matrices(40.0, 20.0, 45.0)
    np.testing.assert_array_equal(sc.plant.A, a)
    np.testing.assert_array_equal(sc.plant.B, b)
    assert sc.plant.model is PlantModel.ROVER and sc.plant.spring_anchor is SpringAnchor.LEG_TARGET
    assert sc.disturbance.model is DisturbanceModel.WORST_CASE and sc.disturbance.gamma == 12.0
    c = sc.controller
    assert c.variant == 'robust' and c.variant is ControllerVariant.ROBUST
    np.testing.assert_array_equal(c.M, 10.0 * np.eye(4))
    np.testing.assert_array_equal(c.R, np.diag([2.0, 3.0]))
    np.testing.assert_array_equal(c.P_T, 0.5 * np.eye(4))
    assert (c.alpha_c, c.alpha_a, c.alpha_d, c.gamma, c.rho, c.forces) == (90.0, 1.2, 2.5, 12.0, 0.15, ())
    assert sc.planner.steer_distance == 2.0 and sc.planner.iterations_per_step == 30
    by_id = {o.id: o for o in sc.obstacles}
    assert list(by_id) == ['box1', 'late', 'gone', 'small_otte_0', 'small_otte_1', 'small_otte_2']
    assert by_id['late'].appear_at == 40.0 and not by_id['late'].known
    assert by_id['gone'].known and by_id['gone'].vanish_at == 0.0 and not by_id['gone'].ever_exists
    assert by_id['gone'].polygon.shape == (32, 2)
    flags = [(o.known, o.vanish_at) for o in sc.obstacles[3:]]
    assert flags == [(True, math.inf), (False, math.inf), (True, 0.0)]
    with pytest.raises(ValueError):
        sc.start[0] = 1.0  # frozen all the way down


def test_defaults_follow_design_example():
    sc = parse()
    assert sc.name == 'inline' and sc.seed == 0 and sc.duration == 300.0
    assert (sc.perception_radius, sc.robot_radius) == (8.0, 0.0)
    p = sc.plant
    assert (p.mass, p.stiffness, p.damping, p.force_limit) == (40.0, 20.0, 45.0, 1000.0)
    assert p.spring_anchor is SpringAnchor.LEG_TARGET
    assert sc.disturbance.model is DisturbanceModel.NONE
    np.testing.assert_array_equal(sc.disturbance.F, [[0], [0], [-1], [1]])
    c = sc.controller
    assert (c.variant, c.horizon, c.dt, c.rho) == ('nominal', 10.0, 0.05, 0.15)
    np.testing.assert_array_equal(c.M, 10.0 * np.eye(4))
    # 0.02, not the paper's 2: at R = 2 the finite-horizon optimum on a rover without a spring
    # moves 0.5 m of a 5 m leg in 10 s (docs/scenarios.md, controller keys)
    np.testing.assert_array_equal(c.R, 0.02 * np.eye(2))
    assert c.force_limit == p.force_limit
    assert c.alpha_c is None and c.gamma is None
    assert sc.planner.epsilon == 0.0 and sc.obstacles == ()
    assert sc.planner.stall_time == 10.0 and sc.planner.rrtx((0.0, 0.0)).stall_time == 10.0
    assert parse(planner={'stall_time': math.inf}).planner.rrtx((0.0, 0.0)).stall_time == math.inf


def test_sensing_defaults_are_exact_and_undelayed_and_the_keys_are_read():
    sc = parse()
    assert sc.plant.actuation_delay == 0.0
    assert (sc.odometry_noise.position_std, sc.odometry_noise.velocity_std) == (0.0, 0.0)
    sc = parse(plant={'actuation_delay': 0.15, 'odometry_noise': {'position': 0.02,
                                                                  'velocity': 0.1}})
    assert sc.plant.actuation_delay == 0.15
    assert (sc.odometry_noise.position_std, sc.odometry_noise.velocity_std) == (0.02, 0.1)
    lti = {'model': 'lti', 'A': [[0, 1], [0, 0]], 'B': [[0], [1]], 'actuation_delay': 0.3,
           'odometry_noise': {'velocity': 0.5}}
    sc = parse(plant=lti, controller={'R': 1.0, 'dt': 0.1})
    assert sc.plant.actuation_delay == 0.3 and sc.odometry_noise.velocity_std == 0.5


def test_seed_override_and_builders():
    sc = load_scenario(DATA / 'full.yaml', seed=11)
    assert sc.seed == 11
    plant = build_plant(sc)
    assert (plant.n, plant.m, plant.q, plant.dt) == (4, 2, 1, 0.05)
    gen = build_disturbance(sc, np.random.default_rng(0))
    d = gen.value(0.0, np.array([5.0, -5.0, 0.0, 0.0]), 10.0)
    assert d.shape == (1,) and 0.0 < abs(d[0]) <= 1.0


def test_lti_plant_and_open_loop_profile():
    sc = parse(
        plant={'model': 'lti', 'A': [[0, 0, 1, 0], [0, 0, 0, 1], [0, 0, 0, 0], [0, 0, 0, 0]],
               'B': [[0, 0], [0, 0], [1, 0], [0, 1]], 'spring_anchor': 'world_origin'},
        controller={'variant': 'open_loop', 'forces': [[1.0, 5.0, 0.0], [2.5, 0.0, -3.0]]},
    )  # fmt: skip
    assert sc.plant.model is PlantModel.LTI and math.isnan(sc.plant.mass)
    assert sc.plant.spring_anchor is SpringAnchor.WORLD_ORIGIN
    f = sc.controller.forces
    assert f == ((1.0, 5.0, 0.0), (2.5, 0.0, -3.0))


def test_lti_with_other_state_size_needs_f_only_when_used():
    plant = {'model': 'lti', 'A': [[0, 1], [0, 0]], 'B': [[0], [1]]}
    sc = parse(plant=plant, controller={'R': 1.0})
    assert sc.disturbance.F.shape == (2, 1) and not sc.disturbance.F.any()
    with pytest.raises(ScenarioError) as info:
        parse(plant=plant, controller={'R': 1.0}, disturbance={'model': 'constant'})
    assert info.value.key == 'disturbance.F'


def test_otte_without_discoverable_uses_entry_keys(tmp_path):
    (tmp_path / 'w.txt').write_text((DATA / 'small_otte.txt').read_text())
    data = copy.deepcopy(BASE) | {'obstacles': [{'file': 'w.txt', 'known': True, 'appear_at': 3.0}]}
    sc = parse_scenario(data, str(tmp_path / 's.yaml'))
    assert [(o.id, o.known, o.appear_at, o.vanish_at) for o in sc.obstacles] == [
        (f'w_{i}', True, 3.0, math.inf) for i in range(3)
    ]


def test_goal_inside_a_never_existing_obstacle_is_fine():
    sc = parse(obstacles=[{'id': 'ghost', 'circle': {'center': [8, 8], 'radius': 1}, 'known': True, 'vanish_at': 0.0}])
    assert sc.obstacles[0].id == 'ghost'


def test_start_inside_a_late_obstacle_is_fine():
    sc = parse(obstacles=[{'id': 'late', 'circle': {'center': [-8, -8], 'radius': 1}, 'appear_at': 5.0}])
    assert sc.obstacles[0].appear_at == 5.0


SQ = [[-1, -1], [1, -1], [1, 1], [-1, 1]]
ERRORS = [
    # (overrides, key, message fragment)
    ({'colour': 1}, 'colour', 'allowed: name'),
    ({'plant': {'mass': 40, 'A': [[0]]}}, 'plant.A', 'allowed'),
    ({'plant': {'model': 'lti', 'A': [[0, 1], [0, 0]], 'B': [[0], [1]], 'mass': 3}}, 'plant.mass', 'allowed'),
    ({'controller': {'Q': 1}}, 'controller.Q', 'allowed'),
    ({'obstacles': [{'id': 'a', 'polygon': SQ, 'colour': 3}]}, 'obstacles[0].colour', 'allowed'),
    ({'bounds': {'x': [0, 1], 'y': [0, 1], 'z': [0, 1]}}, 'bounds.z', 'allowed'),
    ({'plant': {'mass': 0}}, 'plant.mass', '> 0'),
    ({'plant': {'mass': '.nan'}}, 'plant.mass', 'number'),
    ({'plant': {'mass': math.nan}}, 'plant.mass', 'finite'),
    ({'plant': {'mass': '1e3'}}, 'plant.mass', '1.0e3'),
    ({'plant': {'damping': -1}}, 'plant.damping', '>= 0'),
    ({'plant': {'force_limit': 0}}, 'plant.force_limit', '> 0'),
    ({'plant': {'model': 'boat'}}, 'plant.model', 'rover, lti'),
    ({'plant': {'spring_anchor': 'moon'}}, 'plant.spring_anchor', 'leg_target'),
    ({'plant': {'model': 'lti', 'B': [[1]]}}, 'plant.A', 'required'),
    ({'plant': {'model': 'lti', 'A': [[0, 1], [0]], 'B': [[0], [1]]}}, 'plant.A', 'row 1'),
    ({'plant': {'model': 'lti', 'A': [[0, 1, 0], [0, 0, 1]], 'B': [[0], [1]]}}, 'plant.A', 'n x n'),
    ({'plant': {'model': 'lti', 'A': [[0, 1], [0, 0]], 'B': [[0], [1], [2]]}}, 'plant.B', 'shape'),
    ({'plant': []}, 'plant', 'mapping'),
    ({'plant': {'actuation_delay': -0.05}}, 'plant.actuation_delay', '>= 0'),
    ({'plant': {'actuation_delay': 0.07}}, 'plant.actuation_delay', 'multiple of the step'),
    ({'plant': {'actuation_delay': 0.1}, 'controller': {'dt': 0.03}}, 'plant.actuation_delay',
     'dt = 0.03'),
    ({'plant': {'actuation_delay': '.inf'}}, 'plant.actuation_delay', 'number'),
    ({'plant': {'odometry_noise': {'position': -0.1}}}, 'plant.odometry_noise.position', '>= 0'),
    ({'plant': {'odometry_noise': {'velocity': 'some'}}}, 'plant.odometry_noise.velocity',
     'number'),
    ({'plant': {'odometry_noise': {'heading': 0.1}}}, 'plant.odometry_noise.heading',
     'allowed: position, velocity'),
    ({'plant': {'odometry_noise': 0.1}}, 'plant.odometry_noise', 'mapping'),
    ({'disturbance': {'model': 'gale'}}, 'disturbance.model', 'worst_case'),
    ({'disturbance': {'F': [[1], [2]]}}, 'disturbance.F', 'shape 4x'),
    ({'disturbance': {'model': 'gaussian', 'amplitude': -1}}, 'disturbance.amplitude', '>= 0'),
    ({'disturbance': {'model': 'worst_case'}}, 'disturbance.gamma', 'required'),
    ({'disturbance': {'model': 'worst_case', 'gamma': 2.0}}, 'disturbance.gamma', 'game bound'),
    ({'controller': {'variant': 'robust'}}, 'controller.gamma', 'required'),
    ({'controller': {'variant': 'robust', 'gamma': 3.0}}, 'controller.gamma', 'game bound'),
    ({'controller': {'variant': 'fancy'}}, 'controller.variant', 'open_loop'),
    ({'controller': {'variant': 'open_loop'}}, 'controller.forces', 'required'),
    ({'controller': {'forces': [[0, 1, 1]]}}, 'controller.forces', 'only for the open_loop'),
    ({'controller': {'variant': 'open_loop', 'forces': [[1, 0, 0], [1, 2, 2]]}}, 'controller.forces[1]', 'increasing'),
    ({'controller': {'variant': 'open_loop', 'forces': [[1, 0]]}}, 'controller.forces[0]', '[t, fx, fy]'),
    ({'controller': {'variant': 'open_loop', 'forces': []}}, 'controller.forces', 'non-empty'),
    ({'controller': {'measured_disturbance': 'yes'}}, 'controller.measured_disturbance', 'true or false'),
    ({'controller': {'alpha_c': 0.0}}, 'controller.alpha_c', '> 0'),
    ({'controller': {'alpha_a': -1.0}}, 'controller.alpha_a', '> 0'),
    ({'controller': {'dt': 2.0, 'horizon': 1.0}}, 'controller.dt', 'horizon'),
    ({'controller': {'dt': 0}}, 'controller.dt', '> 0'),
    ({'controller': {'horizon': -3}}, 'controller.horizon', '> 0'),
    ({'controller': {'M': [[1, 0], [0, 1]]}}, 'controller.M', 'shape 4x4'),
    ({'controller': {'R': 0.0}}, 'controller.R', '> 0'),
    ({'controller': {'R': [[1, 2], [2, 1]]}}, 'controller.R', 'positive definite'),
    ({'controller': {'R': [[1, 0.5], [0, 1]]}}, 'controller.R', 'symmetric'),
    ({'controller': {'P_T': -1}}, 'controller.P_T', '>= 0'),
    ({'controller': {'rho': 0}}, 'controller.rho', '> 0'),
    ({'safety': {'margin': 'max'}}, 'safety.margin', 'running_max, conformal, learned_bound'),
    ({'safety': {'confidence': 1.0}}, 'safety.confidence', '< 1'),
    ({'safety': {'confidence': 0}}, 'safety.confidence', '> 0'),
    ({'safety': {'window': 0}}, 'safety.window', '>= 1'),
    ({'safety': {'window': 2.5}}, 'safety.window', 'integer'),
    ({'safety': {'initial_margin': -0.1}}, 'safety.initial_margin', '>= 0'),
    ({'safety': {'initial_margin': 'big'}}, 'safety.initial_margin', 'number'),
    ({'safety': {'prior_bound': 0.0}}, 'safety.prior_bound', '> 0'),
    ({'safety': {'delta': 0.1}}, 'safety.delta', 'allowed: margin'),
    ({'safety': [1]}, 'safety', 'mapping'),
    ({'safety': {'calibration': 'scores.json'}}, 'safety.calibration', 'only for margin: conformal'),
    ({'safety': {'margin': 'conformal', 'calibration': 'nope.json'}}, 'safety.calibration', 'cannot read'),
    ({'safety': {'margin': 'learned_bound', 'conformal': 'yes'}}, 'safety.conformal', ''),
    ({'disturbance': {'model': 'field'}}, 'disturbance.bumps', 'non-empty list'),
    ({'disturbance': {'model': 'field', 'bumps': [{'center': [0, 0], 'value': [1, 0]}]}},
     'disturbance.bumps[0].radius', 'required'),
    ({'disturbance': {'model': 'field', 'bumps': [{'center': [0, 0], 'radius': 0, 'value': [1, 0]}]}},
     'disturbance.bumps[0].radius', '> 0'),
    ({'disturbance': {'model': 'field', 'bumps': [{'center': [0], 'radius': 1, 'value': [1, 0]}]}},
     'disturbance.bumps[0].center', '[x, y]'),
    ({'disturbance': {'model': 'field', 'bumps': [{'center': [0, 0], 'radius': 1, 'value': [1, 0], 'sign': 1}]}},
     'disturbance.bumps[0].sign', 'allowed'),
    ({'disturbance': {'model': 'field', 'F': [[0], [0], [1], [0]], 'bumps': [{'center': [0, 0], 'radius': 1, 'value': [1, 0]}]}},
     'disturbance.F', 'not for model field'),
    ({'disturbance': {'model': 'constant', 'bumps': []}}, 'disturbance.bumps', 'only for model field'),
    ({'duration': 0}, 'duration', '> 0'),
    ({'perception_radius': -1}, 'perception_radius', '> 0'),
    ({'robot_radius': -0.1}, 'robot_radius', '>= 0'),
    ({'seed': -1}, 'seed', 'integer'),
    ({'seed': 1.5}, 'seed', 'integer'),
    ({'name': ''}, 'name', 'string'),
    ({'planner': [1, 2]}, 'planner', 'mapping'),
    ({'planner': {'iterations_per_step': 1.5}}, 'planner.iterations_per_step', 'integer'),
    ({'planner': {'steer': 1.0}}, 'planner.steer', 'unknown key'),
    ({'planner': {'stall_time': 0.0}}, 'planner.stall_time', '> 0'),
    ({'planner': {'stall_time': float('nan')}}, 'planner.stall_time', 'finite'),
    ({'bounds': {'x': [1, -1], 'y': [0, 1]}}, 'bounds.x', 'min < max'),
    ({'bounds': {'x': [0, 1]}}, 'bounds.y', 'required'),
    ({'start': [0, 0, 0]}, 'start', '[x, y]'),
    ({'start': [0, True]}, 'start[1]', 'number'),
    ({'start': [-11, 0]}, 'start', 'outside the bounds'),
    ({'goal': [0, 10.5]}, 'goal', 'outside the bounds'),
    ({'obstacles': {'id': 'a'}}, 'obstacles', 'list'),
    ({'obstacles': [{'id': 'a'}]}, 'obstacles[0]', 'exactly one of'),
    ({'obstacles': [{'id': 'a', 'polygon': SQ, 'circle': {}}]}, 'obstacles[0]', 'exactly one of'),
    ({'obstacles': [{'polygon': SQ}]}, 'obstacles[0].id', 'required'),
    ({'obstacles': [{'id': 'a', 'polygon': [[0, 0], [1, 1]]}]}, 'obstacles[0].polygon', 'at least 3'),
    ({'obstacles': [{'id': 'a', 'polygon': [[0, 0], [1, 1], [2]]}]}, 'obstacles[0].polygon[2]', '[x, y]'),
    ({'obstacles': [{'id': 'a', 'polygon': [[0, 0], [1, 1], [2, 2]]}]}, 'obstacles[0].polygon', 'zero area'),
    ({'obstacles': [{'id': 'a', 'polygon': [[0, 0], [1, 0], [0, '.inf']]}]}, 'obstacles[0].polygon[2][1]', 'number'),
    ({'obstacles': [{'id': 'a', 'circle': {'center': [0, 0], 'radius': 0}}]}, 'obstacles[0].circle.radius', '> 0'),
    ({'obstacles': [{'id': 'a', 'circle': {'center': [0, 0]}}]}, 'obstacles[0].circle.radius', 'required'),
    ({'obstacles': [{'id': 'a', 'circle': {'center': [0, 0], 'r': 1}}]}, 'obstacles[0].circle.r', 'allowed'),
    ({'obstacles': [{'id': 'a', 'polygon': SQ, 'appear_at': 5, 'vanish_at': 2}]}, 'obstacles[0].vanish_at', 'before'),
    ({'obstacles': [{'id': 'a', 'polygon': SQ, 'known': 'yes'}]}, 'obstacles[0].known', 'true or false'),
    (
        {'obstacles': [{'id': 'a', 'polygon': SQ}, {'id': 'a', 'circle': {'center': [3, 3], 'radius': 1}}]},
        'obstacles[1].id',
        'duplicate',
    ),
    ({'obstacles': [{'id': 3, 'polygon': SQ}]}, 'obstacles[0].id', 'string'),
    ({'obstacles': [{'file': 'nope.txt'}]}, 'obstacles[0].file', 'cannot read'),
    ({'obstacles': [{'file': 'small_otte.txt', 'format': 'svg'}]}, 'obstacles[0].format', 'otte'),
    ({'obstacles': [{'file': 'small_otte.txt', 'discoverable': True, 'known': True}]}, 'obstacles[0].known', 'flags'),
    ({'obstacles': [{'file': 'small_otte.txt'}, {'file': 'small_otte.txt'}]}, 'obstacles[1].file', 'duplicate'),
    ({'obstacles': [{'id': 's', 'polygon': [[-9, -9], [-7, -9], [-7, -7], [-9, -7]]}]}, 'start', "inside obstacle 's'"),
    (
        {'obstacles': [{'id': 'g', 'polygon': [[7, 7], [9, 7], [9, 9]], 'appear_at': 50, 'vanish_at': 60}]},
        'goal',
        "inside obstacle 'g'",
    ),
    (
        {'robot_radius': 0.5, 'obstacles': [{'id': 'g', 'circle': {'center': [8, 9], 'radius': 0.6}}]},
        'goal',
        "inside obstacle 'g'",
    ),
]


@pytest.mark.parametrize(('overrides', 'key', 'fragment'), ERRORS)
def test_bad_input_names_file_and_key(overrides, key, fragment):
    with pytest.raises(ScenarioError) as info:
        parse(**overrides)
    err = info.value
    assert err.key == key
    assert fragment in err.message
    assert str(err) == f"{DATA / 'inline.yaml'}: {key}: {err.message}"


def test_robot_radius_grows_obstacles_only_when_positive():
    obstacle = {'id': 'g', 'circle': {'center': [8, 9.7], 'radius': 0.6}}
    assert parse(obstacles=[obstacle]).goal.tolist() == [8.0, 8.0]
    with pytest.raises(ScenarioError, match='goal'):
        parse(robot_radius=1.2, obstacles=[obstacle])


def test_undiscoverable_file_rejects_discoverable(tmp_path):
    (tmp_path / 'b.txt').write_text('1\n3\n0,0\n1,0\n0,1\n')
    data = copy.deepcopy(BASE) | {'obstacles': [{'file': 'b.txt', 'discoverable': True}]}
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, str(tmp_path / 's.yaml'))
    assert info.value.key == 'obstacles[0].discoverable'


def test_malformed_otte_file_reports_line(tmp_path):
    (tmp_path / 'b.txt').write_text('1\n3\n0,0\nbad\n0,1\n')
    data = copy.deepcopy(BASE) | {'obstacles': [{'file': 'b.txt'}]}
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, str(tmp_path / 's.yaml'))
    assert info.value.key == 'obstacles[0].file' and 'b.txt:4:' in info.value.message


@pytest.mark.parametrize(
    ('text', 'fragment'),
    [
        ('bounds: {x: [0, 1]\n', 'YAML error'),
        ('- 1\n- 2\n', 'top level must be a mapping'),
        ('', 'top level must be a mapping'),
        ('start: [0, 0]\nstart: [1, 1]\n', "duplicate key 'start'"),
    ],
)
def test_unreadable_documents(tmp_path, text, fragment):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.key == '' and fragment in info.value.message and str(path) in str(info.value)


def test_missing_file_and_bad_seed_override(tmp_path):
    with pytest.raises(ScenarioError, match='cannot read'):
        load_scenario(tmp_path / 'absent.yaml')
    with pytest.raises(ScenarioError) as info:
        load_scenario(DATA / 'full.yaml', seed=-2)
    assert info.value.key == 'seed'


def test_required_top_level_keys():
    for name in ('bounds', 'start', 'goal'):
        data = copy.deepcopy(BASE)
        del data[name]
        with pytest.raises(ScenarioError) as info:
            parse_scenario(data, 'x.yaml')
        assert info.value.key == name


def test_yaml_round_trip_of_the_inline_base(tmp_path):
    path = tmp_path / 'mission.yaml'
    path.write_text(yaml.safe_dump(BASE))
    sc = load_scenario(path)
    assert sc.name == 'mission' and sc.path == str(path)


def test_scenario_appear_clearance_reaches_the_truth():
    base = {'bounds': {'x': [-5, 5], 'y': [-5, 5]}, 'start': [-4, 0], 'goal': [4, 0], 'robot_radius': 0.5,
            'obstacles': [{'id': 'due', 'polygon': [[-3, -1], [-2, -1], [-2, 1], [-3, 1]], 'appear_at': 1.0}]}
    assert parse_scenario(base, 's.yaml').appear_clearance == 1.0
    truth = TrueObstacles.for_scenario(parse_scenario(base | {'appear_clearance': 0.2}, 's.yaml'))
    assert truth.update([-3.6, 0.0], 1.0) == ()            # disc 0.1 m away: within 0.2
    assert [s.id for s in truth.update([-4.0, 0.0], 1.1)] == ['due']   # 0.5 m: clear
    with pytest.raises(ScenarioError, match='appear_clearance'):
        parse_scenario(base | {'appear_clearance': -1.0}, 's.yaml')


def test_safety_section_defaults_and_a_calibration_read_from_the_scenario_directory(tmp_path):
    from rrtq_planner.margins.calibration import Calibration, write_calibration
    from rrtq_planner.margins.policy import MarginMode
    sc = parse()
    assert sc.margins.margin is MarginMode.RUNNING_MAX and sc.margins.confidence == 0.95
    assert sc.margins.window == 50 and sc.margins.initial_margin is None
    assert sc.margins.prior_bound == 0.1 and sc.margins.conformal is True
    sc = parse(safety={'margin': 'learned_bound', 'prior_bound': 0.1, 'conformal': False})
    assert sc.margins.margin is MarginMode.LEARNED_BOUND and sc.margins.prior_bound == 0.1
    assert sc.margins.conformal is False
    write_calibration(tmp_path / 'scores.json', Calibration((0.2, 0.4)))
    data = copy.deepcopy(BASE) | {'safety': {'margin': 'conformal', 'confidence': 0.9,
                                             'window': 20, 'initial_margin': 0.3,
                                             'calibration': 'scores.json'}}
    sc = parse_scenario(data, str(tmp_path / 'mission.yaml'))
    assert sc.margins.margin is MarginMode.CONFORMAL and sc.margins.window == 20
    assert sc.margins.calibration == str(tmp_path / 'scores.json')
    assert (sc.margins.confidence, sc.margins.initial_margin) == (0.9, 0.3)
    # learned_bound takes a calibration too (its normalized and prior scores).
    data['safety'] |= {'margin': 'learned_bound'}
    assert parse_scenario(data, str(tmp_path / 'm.yaml')).margins.calibration is not None


@pytest.mark.parametrize(('text', 'fragment'), [
    ('{"format": "rrtq-margin-calibration", "version": 1, "scores": [0.1, -2]}', 'scores'),
    ('{"format": "rrtq-margin-calibration", "version": 4, "scores": []}', 'version 4'),
    ('{"scores": [0.1', 'not a JSON'),
])
def test_bad_calibration_file_names_the_scenario_key_and_the_file(tmp_path, text, fragment):
    (tmp_path / 'scores.json').write_text(text)
    data = copy.deepcopy(BASE) | {'safety': {'margin': 'conformal',
                                             'calibration': 'scores.json'}}
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, str(tmp_path / 'mission.yaml'))
    assert info.value.key == 'safety.calibration'
    assert str(tmp_path / 'scores.json') in info.value.message and fragment in info.value.message


def test_field_disturbance_is_the_sum_of_its_bumps_where_the_robot_is():
    sc = parse(disturbance={'model': 'field', 'bumps': [
        {'center': [1.0, 2.0], 'radius': 2.0, 'value': [0.5, -0.25]},
        {'center': [-3.0, 0.0], 'radius': 1.0, 'value': [0.0, 1.0]}]})
    assert sc.disturbance.model is DisturbanceModel.FIELD and sc.disturbance.q == 2
    np.testing.assert_array_equal(sc.disturbance.F, [[0, 0], [0, 0], [1, 0], [0, 1]])
    gen = build_disturbance(sc, np.random.default_rng(0))
    # At a centre the bump's value; at half its radius exp(1 - 1/(1 - 1/4)) = e^(-1/3) of it.
    np.testing.assert_allclose(gen.value_at(0.0, [1.0, 2.0, 5.0, 5.0], [9.0, 9.0], 3.0),
                               [0.5, -0.25])
    np.testing.assert_allclose(gen.value_at(7.0, [-3.0, 0.5, 0.0, 0.0], None, 0.0),
                               [0.0, math.exp(-1.0 / 3.0)])
    np.testing.assert_array_equal(gen.value_at(0.0, [5.0, 5.0, 0.0, 0.0], None, 0.0), [0, 0])
