"""Safe while learning, from the defaults: a scenario with no controller keys at all.

The rover without a spring, the plant's default force limit, no initial gain, no probing or
gain settings, default steer distance and robot radius, a 30 x 30 m square with three
obstacles (one known, two found on the way): the run a new user writes first. Judged from
the recording alone, as outside checks do.
"""

import pathlib
import subprocess

import numpy as np

from rrtq_bringup.leg_costs import evaluate
from rrtq_bringup.leg_table import summary
from rrtq_bringup.report import summarise
from rrtq_bringup.run_data import embedded_scenario, read_run

ROOT = pathlib.Path(__file__).resolve().parents[1]

DEFAULTS_ONLY = """
name: defaults-only
seed: 3
bounds: {x: [-15, 15], y: [-15, 15]}
start: [-11.0, -11.0]
goal: [11.0, 11.0]
plant: {model: rover, stiffness: 0.0}
obstacles:
  - {id: a, polygon: [[-7, -4], [-3, -4], [-3, -2], [-7, -2]], known: true}
  - {id: b, polygon: [[-1, -3], [1, -3], [1, 5], [-1, 5]]}
  - {id: c, circle: {center: [6, 3], radius: 1.5}, appear_at: 20.0}
"""


def test_a_defaults_only_scenario_learns_safely_and_reaches_its_goal(tmp_path):
    path = tmp_path / 'defaults.yaml'
    path.write_text(DEFAULTS_ONLY)
    out = tmp_path / 'run'
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    data = read_run(out / 'run.mcap')
    judged = summarise(data, embedded_scenario(out / 'run.mcap'))
    assert judged['time_to_goal_s'] is not None and judged['collided'] is False
    # the controller knew the plant's limit (1000 N, the default) and never commanded beyond it
    assert data.force_limit == 1000.0
    assert np.abs(data.cmd_u).max() <= data.force_limit
    # it learned through the guard: adoptions recorded, and no leg ran away from its target
    events = [e for _, e, _ in data.policy_events]
    assert events.count('adopted') >= 3
    assert 'reverted' not in events and 'hold' not in events
    assert judged['max_d_rob_m'] < 5.0
    # each leg's cost against the Riccati optimum from its start, the last ten legs
    table = summary(evaluate(out / 'run.mcap'))
    assert table['legs'] >= 10
    assert table['median_ratio_last10'] <= 1.05, table['ratios_last10']
