"""Safe while learning, from the defaults: a scenario with no controller keys at all.

The rover without a spring, the plant's default force limit, no initial gain, no probing or
gain settings, default steer distance and robot radius, a 50 x 50 m square with four
obstacles (one known, three found on the way): the run a new user writes first. Judged from
the recording alone, as outside checks do. This layout once ran out of its 300 s 13 m short
of the goal: the hold before the first path "completed a leg" under the zero gain (which
made the guard ask a positive-definite value of every early proposal and reject them for
55 s), and, with that mended, the critic's greedy gain below the times-to-go its samples
covered was an extrapolation that pushed the robot away at the end of long legs
(docs/design.md, Controller: coverage).

The second scenario is a heavier rover with a lower force limit (110 kg, 15 kg/s: a 7 s
time constant; 200 N), also from the defaults. Its early policies diverge before any
completed a leg; a hold to the zero gain let it coast on (the run then ended with the goal
cut off by the margin that coasting grew), and the hold now brakes (guard.Brake).
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
seed: 7
bounds: {x: [-25, 25], y: [-25, 25]}
start: [20.0, -20.0]
goal: [-18.0, 19.0]
plant: {model: rover, stiffness: 0.0}
obstacles:
  - {id: a, polygon: [[5, -10], [12, -10], [12, -6], [5, -6]], known: true}
  - {id: b, circle: {center: [0, 0], radius: 3.0}}
  - {id: c, polygon: [[-12, 5], [-8, 5], [-8, 14], [-12, 14]], appear_at: 15.0}
  - {id: d, circle: {center: [-5, 10], radius: 2.0}, appear_at: 30.0}
"""


HEAVY_LOW_LIMIT = """
name: heavy-low-limit
seed: 11
bounds: {x: [-20, 20], y: [-20, 20]}
start: [-16.0, 14.0]
goal: [15.0, -14.0]
plant: {model: rover, mass: 110.0, damping: 15.0, stiffness: 0.0, force_limit: 200.0}
obstacles:
  - {id: a, polygon: [[-9, 4], [-3, 4], [-3, 8], [-9, 8]], known: true}
  - {id: b, circle: {center: [2, 0], radius: 3.0}}
  - {id: c, polygon: [[6, -10], [9, -10], [9, -3], [6, -3]], appear_at: 25.0}
  - {id: d, circle: {center: [-4, -6], radius: 2.5}, appear_at: 10.0}
"""


def _run(tmp_path, text):
    path = tmp_path / 'scenario.yaml'
    path.write_text(text)
    out = tmp_path / 'run'
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    data = read_run(out / 'run.mcap')
    return out, data, summarise(data, embedded_scenario(out / 'run.mcap'))


def test_a_heavier_rover_with_a_lower_limit_brakes_when_it_holds_and_reaches_its_goal(tmp_path):
    out, data, judged = _run(tmp_path, HEAVY_LOW_LIMIT)
    assert judged['time_to_goal_s'] is not None and judged['collided'] is False
    assert data.force_limit == 200.0
    assert np.abs(data.cmd_u).max() <= 200.0
    holds = [reason for _, e, reason in data.policy_events if 'hold' in e.split(';')]
    assert holds and all('braking' in reason for reason in holds)
    table = summary(evaluate(out / 'run.mcap'))
    assert table['median_ratio_last10'] <= 1.05, table['ratios_last10']


def test_a_defaults_only_scenario_learns_safely_and_reaches_its_goal(tmp_path):
    out, data, judged = _run(tmp_path, DEFAULTS_ONLY)
    assert judged['time_to_goal_s'] is not None and judged['collided'] is False
    # the controller knew the plant's limit (1000 N, the default) and never commanded beyond it
    assert data.force_limit == 1000.0
    assert np.abs(data.cmd_u).max() <= data.force_limit
    # it learned through the guard: adoptions recorded, and no leg ran away from its target
    # (D or the speed); a leg may have braked where it left its line past the margin
    events = [e for _, e, _ in data.policy_events]
    assert events.count('adopted') >= 3
    stops = [(e, reason) for _, e, reason in data.policy_events
             if {'reverted', 'hold'} & set(e.split(';'))]
    assert all('off its line' in reason and 'braking' in reason for _, reason in stops), stops
    assert judged['max_d_rob_m'] < 5.0
    # each leg's cost against the Riccati optimum from its start, the last ten legs
    table = summary(evaluate(out / 'run.mcap'))
    assert table['legs'] >= 10
    assert table['median_ratio_last10'] <= 1.05, table['ratios_last10']
