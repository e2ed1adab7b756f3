"""The VF-LPC keys: planner.guidance, controller.variant vf_lpc, controller.model, controller.vf_lpc.

Defaults leave today's graph as it was (waypoints, no guidance parameters or topic); every
bad value, file or combination is an error naming the file and the key, found before
anything starts.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from rrtq_bringup.graph import build_graph
from rrtq_bringup.scenario import ScenarioError, parse_scenario
from rrtq_common import topics
from rrtq_controller.config import Variant
from rrtq_controller.vf_lpc import fit_edmd
from rrtq_planner.guidance import GuidanceMode
from rrtq_testing.controller_reference import rover, zoh

BASE = {'bounds': {'x': [-10, 10], 'y': [-10, 10]}, 'start': [-8.0, -8.0], 'goal': [8.0, 8.0],
        'plant': {'model': 'rover', 'stiffness': 0.0}}


@pytest.fixture(scope='module')
def model_file(tmp_path_factory):
    """A model identified (EDMD) on the 40 kg rover without a spring, dt 0.05 s."""
    a, b = zoh(*rover(stiffness=0.0), 0.05)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 4))
    u = rng.normal(scale=100.0, size=(200, 2))
    path = tmp_path_factory.mktemp('model') / 'rover.npz'
    fit_edmd(x, u, x @ a.T + u @ b.T, 0.05, force_limit=1000.0).save(path)
    return path


def parse(where, **overrides):
    data = copy.deepcopy(BASE) | overrides
    return parse_scenario(data, str(where / 'scenario.yaml'))


def vf_lpc(model, **controller):
    return {'variant': 'vf_lpc', 'model': str(model), **controller}


GVF = {'guidance': {'mode': 'gvf'}}


def test_defaults_keep_the_waypoint_graph(tmp_path):
    sc = parse(tmp_path)
    assert sc.guidance.mode is GuidanceMode.WAYPOINTS
    specs = {s.name: s for s in build_graph(sc, 0.0, str(tmp_path / 'r.mcap'))}
    assert 'mode' not in specs['planner'].params and 'k_path' not in specs['planner'].params
    assert 'horizon_steps' not in specs['controller'].params
    assert not any(topics.GUIDANCE_REFERENCE in s.subscribes for s in specs.values())
    wait = specs['simulator'].params['wait_for']
    assert not any(w.startswith(topics.GUIDANCE_REFERENCE) for w in wait)


def test_vf_lpc_scenario_reads_its_keys_and_wires_the_graph(tmp_path, model_file):
    sc = parse(tmp_path, controller=vf_lpc(model_file, vf_lpc={'horizon_steps': 15,
                                                               'compensate': False}),
               planner={'guidance': {'mode': 'gvf', 'k_path': 2.0, 'reactive_width': 1.5,
                                     'a_max': 1.5, 'v_max': 1.8}})
    assert sc.controller.variant is Variant.VF_LPC and sc.controller.model == str(model_file)
    assert (sc.lpc.horizon_steps, sc.lpc.compensate, sc.lpc.force_limit) == (15, False, 1000.0)
    g = sc.guidance
    assert (g.mode, g.k_path, g.reactive_width, g.a_max, g.v_max, g.dt) == (
        GuidanceMode.GVF, 2.0, 1.5, 1.5, 1.8, sc.controller.dt)
    specs = {s.name: s for s in build_graph(sc, 0.0, str(tmp_path / 'r.mcap'))}
    assert specs['planner'].params['mode'] == 'gvf' and 'dt' in specs['planner'].params
    assert specs['planner'].params['dt'] == sc.controller.dt      # the run's, not guidance's
    assert specs['controller'].params['horizon_steps'] == 15
    assert 'force_limit' in specs['controller'].params
    assert topics.GUIDANCE_REFERENCE in specs['controller'].subscribes
    wait = dict(w.rsplit(':', 1) for w in specs['simulator'].params['wait_for'])
    assert wait[topics.GUIDANCE_REFERENCE] == '2'                # controller and recorder


def test_model_path_is_relative_to_the_scenario_file(tmp_path, model_file):
    sc = parse(model_file.parent.parent, controller=vf_lpc(f'{model_file.parent.name}/rover.npz'),
               planner=GVF)
    assert sc.controller.model == str(model_file)


def bad_cases(model, tmp):
    text = tmp / 'not_a_model.npz'
    text.write_text('hello')
    other_dt = tmp / 'dt.npz'
    a, b = zoh(*rover(stiffness=0.0), 0.1)
    x = np.random.default_rng(1).normal(size=(100, 4))
    u = np.random.default_rng(2).normal(size=(100, 2))
    fit_edmd(x, u, x @ a.T + u @ b.T, 0.1).save(other_dt)
    return {
        'no model': ({'controller': {'variant': 'vf_lpc'}, 'planner': GVF},
                     'controller.model', 'required'),
        'missing file': ({'controller': vf_lpc(tmp / 'nope.npz'), 'planner': GVF},
                         'controller.model', str(tmp / 'nope.npz')),
        'not a model': ({'controller': vf_lpc(text), 'planner': GVF}, 'controller.model',
                        str(text)),
        'other dt': ({'controller': vf_lpc(other_dt), 'planner': GVF}, 'controller.model',
                     'dt = 0.1'),
        'waypoints': ({'controller': vf_lpc(model)}, 'planner.guidance.mode', 'gvf'),
        'infinite limit': ({'controller': vf_lpc(model, force_limit=float('inf')),
                            'planner': GVF}, 'controller.force_limit', 'finite'),
        'bad lpc value': ({'controller': vf_lpc(model, vf_lpc={'horizon_steps': 0}),
                           'planner': GVF}, 'controller.vf_lpc.horizon_steps', '>= 1'),
        'lpc force limit': ({'controller': vf_lpc(model, vf_lpc={'force_limit': 5.0}),
                             'planner': GVF}, 'controller.vf_lpc.force_limit', 'unknown key'),
        'compensate not bool': ({'controller': vf_lpc(model, vf_lpc={'compensate': 1}),
                                 'planner': GVF}, 'controller.vf_lpc.compensate', 'true or false'),
        'unknown guidance key': ({'planner': {'guidance': {'mode': 'gvf', 'gain': 1}}},
                                 'planner.guidance.gain', 'unknown key'),
        'guidance dt': ({'planner': {'guidance': {'dt': 0.1}}}, 'planner.guidance.dt',
                        'unknown key'),
        'bad mode': ({'planner': {'guidance': {'mode': 'field'}}}, 'planner.guidance.mode',
                     'waypoints, gvf'),
        'a_max out of range': ({'planner': {'guidance': {'a_max': 0.0}}},
                               'planner.guidance.a_max', '> 0'),
        'offset above width': ({'planner': {'guidance': {'reactive_width': 0.5,
                                                         'repulsive_offset': 0.6}}},
                               'planner.guidance.repulsive_offset', 'below reactive_width'),
    }


@pytest.mark.parametrize('case', ['no model', 'missing file', 'not a model', 'other dt',
                                  'waypoints', 'infinite limit', 'bad lpc value',
                                  'lpc force limit', 'compensate not bool',
                                  'unknown guidance key', 'guidance dt', 'bad mode',
                                  'a_max out of range', 'offset above width'])
def test_bad_vf_lpc_keys_name_the_file_and_the_key(tmp_path, model_file, case):
    overrides, key, words = bad_cases(model_file, tmp_path)[case]
    with pytest.raises(ScenarioError) as err:
        parse(tmp_path, **overrides)
    assert err.value.key == key and err.value.file == str(tmp_path / 'scenario.yaml')
    assert words in err.value.message


def test_other_variants_accept_the_keys_for_a_sweep(tmp_path, model_file):
    # One file serves --set controller.variant=nominal,vf_lpc: the nominal variant keeps
    # the model (checked all the same) and the guidance (the reference is only recorded).
    sc = parse(tmp_path, controller={'variant': 'nominal', 'model': str(model_file)},
               planner=GVF)
    assert sc.controller.variant is Variant.NOMINAL and sc.guidance.mode is GuidanceMode.GVF
    with pytest.raises(ScenarioError) as err:
        parse(tmp_path, controller={'variant': 'nominal', 'model': str(tmp_path / 'x.npz')})
    assert err.value.key == 'controller.model'
