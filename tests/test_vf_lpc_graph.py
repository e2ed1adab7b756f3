"""vf_lpc end to end in the node graph: guidance reference, identified model, online GP.

A short route round an obstacle that appears on the way, with a model identified by
``rrtq identify`` (``scenarios/models/rover_40kg.npz``) on a heavier plant than it was
identified on. Judged from the recording against the scenario's truth: the goal is
reached without collision, no command beyond the actuator limit the scenario sets, the
reference was published every step and the controller answered it; and a lock-step run
repeats: a shorter run of the same file, one process per node, records the same /odom
bytes as the first part of the longer, composed one.
"""

import json
import pathlib
import subprocess

import numpy as np
from mcap.reader import make_reader

from rrtq_bringup.report.run import summarise
from rrtq_bringup.report.vf_lpc import vf_lpc_summary
from rrtq_bringup.run_data import embedded_scenario, read_run

ROOT = pathlib.Path(__file__).resolve().parents[1]
MODEL = ROOT / 'scenarios' / 'models' / 'rover_40kg.npz'
LIMIT = 300.0

SCENARIO = """
name: vf-lpc-short
seed: 3
bounds: {x: [-10, 10], y: [-10, 10]}
start: [-6.0, -6.0]
goal: [6.0, 5.0]
duration: DURATION
perception_radius: 5.0
robot_radius: 0.3
plant: {model: rover, mass: 50.0, stiffness: 0.0}
controller:
  variant: vf_lpc
  model: MODEL
  force_limit: LIMIT
  vf_lpc: {horizon_steps: 20}
planner:
  steer_distance: 3.0
  iterations_per_step: 20
  max_nodes: 800
  guidance: {mode: gvf, a_max: 2.0, v_max: 2.0}
obstacles:
  - {id: mid, circle: {center: [0.0, -0.5], radius: 1.5}, appear_at: 1.0}
"""


def run(tmp, name, duration, mode='composed'):
    path = tmp / f'{name}.yaml'
    path.write_text(SCENARIO.replace('DURATION', str(duration)).replace('MODEL', str(MODEL))
                    .replace('LIMIT', str(LIMIT)))
    out = tmp / name
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', mode], capture_output=True, text=True, timeout=300)
    return proc, out


def odom(out):
    with open(out / 'run.mcap', 'rb') as f:
        return [m.data for _, _, m in make_reader(f).iter_messages(topics=['/odom'])]


def test_vf_lpc_reaches_the_goal_within_the_limit_and_repeats(tmp_path):
    proc, out = run(tmp_path, 'goal', 15.0)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    live = json.loads((out / 'summary.json').read_text())
    assert live['outcome'] == 'goal_reached'
    data = read_run(out / 'run.mcap')
    scenario = embedded_scenario(out / 'run.mcap')
    judged = summarise(data, scenario)
    assert judged['collided'] is False and judged['min_clearance_m'] > 0.0
    assert np.abs(data.cmd_u).max() <= LIMIT
    steps = len(data.odom_t)
    assert data.topics['/guidance/reference'] >= steps - 1
    assert all(s.variant == 'vf_lpc' for s in data.states)
    vf = vf_lpc_summary(data, scenario)
    assert vf['tracking_max_m'] < 0.3 and vf['gp_dictionary'] > 0
    # 50 kg against a model of 40: the GP's mean cuts the one-step velocity error.
    assert vf['velocity_rmse_learned'] < 0.5 * vf['velocity_rmse_nominal']

    short, out_short = run(tmp_path, 'short', 2.0, mode='processes')
    assert short.returncode == 1                # 2 s is too short to arrive
    first = odom(out_short)
    assert len(first) == 41 and first == odom(out)[:len(first)]
