"""rrtq bench end to end: the table agrees with the runs; bad input; Ctrl-C; aggregation."""

import json
import pathlib
import signal
import subprocess
import time

import pytest
import yaml

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rrtq_bringup.bench.control import control_metrics
from rrtq_bringup.bench.layouts import LayoutConfig, generate_layout
from rrtq_bringup.bench.table import aggregate, wilson
from rrtq_bringup.scenario import load_scenario

ROOT = pathlib.Path(__file__).resolve().parents[1]
RRTQ = str(ROOT / 'scripts/rrtq')

# A 12 x 12 m square and an 8.5 m route: about 30 s of sim time a run.
BASE = """
name: bench-small
bounds: {x: [-6, 6], y: [-6, 6]}
start: [-3.0, -3.0]
goal: [3.0, 3.0]
duration: 60.0
perception_radius: 4.0
robot_radius: 0.3
plant: {model: rover, mass: 40.0, stiffness: 20.0, damping: 45.0, spring_anchor: leg_target}
controller: {variant: nominal, horizon: 10.0, dt: 0.05, M: 10.0, R: 2.0, P_T: 0.5,
             alpha_c: 90.0, alpha_a: 1.2, rho: 0.15, probing_std: 2.0}
planner: {steer_distance: 3.0, iterations_per_step: 15, max_nodes: 600}
obstacles:
  - {id: replaced, polygon: [[-1, -1], [1, -1], [1, 1], [-1, 1]]}
"""


def _commands(mcap):
    """Every /cmd_force component of a recording, read with mcap-ros2-support's decoder."""
    with open(mcap, 'rb') as f:
        for _schema, _channel, _message, msg in make_reader(
                f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=['/cmd_force']):
            yield msg.wrench.force.x
            yield msg.wrench.force.y


def bench(*args, timeout=120):
    return subprocess.run([RRTQ, 'bench', *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture
def base(tmp_path):
    path = tmp_path / 'base.yaml'
    path.write_text(BASE)
    return path


def test_two_seeds_table_matches_the_runs(tmp_path, base):
    runs, out = tmp_path / 'runs', tmp_path / 'table'
    proc = bench(base, '--seeds', 2, '--first-seed', 5, '--workers', 2, '--obstacles', 4,
                 '--runs', runs, '--out', out)
    assert proc.returncode == 0, proc.stderr
    assert '2/2' in proc.stderr                                     # the progress bar
    assert "the base scenario's obstacles (1) are replaced" in proc.stderr   # not silently
    table = json.loads((out / 'monte_carlo.json').read_text())
    summaries = {seed: json.loads((runs / f'seed-{seed:03d}' / 'summary.json').read_text())
                 for seed in (5, 6)}
    stats = table['stats']
    assert (stats['runs'], stats['completed']) == (2, 2)
    assert stats['success_rate'] == sum(s['success'] for s in summaries.values()) / 2
    assert stats['collision_rate'] == sum(s['collided'] for s in summaries.values()) / 2
    for seed, summary in summaries.items():
        # Each run is the seed's own layout, run composed and lock-step with that seed.
        assert (summary['seed'], summary['mode'], summary['speed']) == (seed, 'composed', 'max')
        written = yaml.safe_load((runs / f'seed-{seed:03d}' / 'scenario.yaml').read_text())
        layout = generate_layout(load_scenario(base), seed, LayoutConfig(obstacles=4))
        assert written['obstacles'] == [dict(e) for e in layout.obstacles]
        assert (runs / f'seed-{seed:03d}' / 'run.mcap').stat().st_size > 0
        row = next(r for r in table['runs'] if r['seed'] == seed)
        assert row['success'] == summary['success'] and row['outcome'] == summary['outcome']
        if summary['success']:
            assert row['path_over_optimum'] == pytest.approx(
                summary['path_length_m'] / (layout.optimum.length - 0.5))
        # the controller's figures, read from the run's own recording
        control = row['control']
        assert control == control_metrics(runs / f'seed-{seed:03d}')
        assert control['legs'] > 0 and control['ratio_riccati_policy_last10'] >= 0.9
        assert control['max_abs_force_n'] == pytest.approx(
            max(abs(f) for f in _commands(runs / f'seed-{seed:03d}' / 'run.mcap')))
    # The runs' own leg scores, pooled beside the table: a later scenario's calibration.
    pooled = json.loads((out / 'calibration.json').read_text())
    own = [json.loads((runs / f'seed-{seed:03d}' / 'calibration.json').read_text())['scores']
           for seed in (5, 6)]
    assert pooled['scores'] == own[0] + own[1] and len(pooled['scores']) > 2
    assert 'seeds 5, 6' in pooled['source'] and 'calibration.json' in proc.stderr
    assert stats['control']['runs'] == 2
    assert stats['control']['within_10pct'] == sum(
        r['control']['ratio_riccati_policy_last10'] <= 1.10 for r in table['runs'])
    md = (out / 'monte_carlo.md').read_text()
    assert f"| success rate | {100 * stats['success_rate']:.0f} %" in md
    assert 'last-ten leg cost / Riccati policy' in md
    assert f"| collision rate | {100 * stats['collision_rate']:.0f} % |" in md
    assert 'commit ' in md and 'rrtq bench ' in md and 'cores' in md


@pytest.mark.parametrize('args, named', [
    (['missing.yaml'], 'missing.yaml'),
    (['{base}', '--seeds', '0'], '--seeds'),
    (['{base}', '--workers', 'two'], '--workers'),
])
def test_bad_input_exits_2_and_names_it(tmp_path, base, args, named):
    proc = bench(*[a.format(base=base) for a in args], '--runs', tmp_path / 'runs')
    assert proc.returncode == 2 and named in proc.stderr, proc.stderr
    assert not (tmp_path / 'runs').exists()


def test_open_loop_base_and_an_earlier_bench_are_bad_input(tmp_path, base):
    open_loop = tmp_path / 'open.yaml'
    open_loop.write_text(BASE.replace('variant: nominal', 'variant: open_loop')
                         .replace('probing_std: 2.0', 'forces: [[0.0, 1.0, 1.0]]'))
    proc = bench(open_loop, '--runs', tmp_path / 'runs')
    assert proc.returncode == 2 and 'controller.variant' in proc.stderr, proc.stderr
    (tmp_path / 'runs' / 'seed-000').mkdir(parents=True)
    proc = bench(base, '--seeds', 1, '--runs', tmp_path / 'runs')
    assert proc.returncode == 2 and '--overwrite' in proc.stderr, proc.stderr


def test_ctrl_c_stops_the_runs_and_writes_what_completed(tmp_path, base):
    runs = tmp_path / 'runs'
    proc = subprocess.Popen([RRTQ, 'bench', str(base), '--seeds', '3', '--workers', '1',
                             '--runs', str(runs)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    first = runs / 'seed-000' / 'run.mcap'
    deadline = time.monotonic() + 60
    while not first.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert first.exists()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    table = json.loads((runs / 'monte_carlo.json').read_text())
    assert table['interrupted'] == 'SIGINT'
    assert {r['seed']: r['reason'] for r in table['stats']['incomplete']} == {
        0: 'interrupted', 1: 'not started (interrupted)', 2: 'not started (interrupted)'}
    # The interrupted run ended as such: its summary says so.
    assert json.loads((runs / 'seed-000' / 'summary.json').read_text())['outcome'] == 'interrupted'
    assert not (runs / 'seed-001').joinpath('run.mcap').exists()


def _row(seed, success, collided=False, ttg=10.0, path=11.0, replan=(5.0, 9.0)):
    outcome = 'goal_reached' if success else ('collision' if collided else 'duration_elapsed')
    return {'seed': seed, 'status': 'completed', 'optimum_m': 10.0, 'summary': {
        'success': success, 'collided': collided, 'outcome': outcome, 'reason': outcome,
        'time_to_goal_s': ttg if success else None, 'path_length_m': path, 'replans': 3,
        'replan_ms': {'median': replan[0], 'p95': replan[1]},
        'controller_step_ms': {'median': 1.0, 'p95': 2.0}, 'sim_speedup': 2.0,
        'wall_time_s': 30.0}}


def test_aggregate_rates_over_completed_runs_and_ratios_over_successes():
    rows = [_row(0, True, ttg=10.0, path=11.0), _row(1, True, ttg=20.0, path=13.0),
            _row(2, False, collided=True, path=4.0), _row(3, False),
            {'seed': 4, 'status': 'timed out', 'optimum_m': 10.0, 'summary': {}}]
    stats = aggregate(rows)
    assert (stats['runs'], stats['completed'], stats['successes']) == (5, 4, 2)
    assert stats['success_rate'] == 0.5 and stats['collision_rate'] == 0.25
    assert stats['time_to_goal_s']['median'] == 15.0
    assert stats['path_over_optimum']['median'] == pytest.approx(1.2)
    assert stats['outcomes'] == {'goal_reached': 2, 'collision': 1, 'duration_elapsed': 1}
    assert [f['seed'] for f in stats['mission_failures']] == [2, 3]
    assert stats['incomplete'] == [{'seed': 4, 'reason': 'timed out'}]
    low, high = wilson(2, 4)
    assert low < 0.5 < high and wilson(0, 0) is None
