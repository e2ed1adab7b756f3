"""rrtq bench on Ray and sweeps: a local Ray head (127.0.0.1, started here) gives the
local engine's outcomes and /odom bytes; a killed Ray worker's run is retried and
reported; --set runs the cross product and rejects a bad key with exit 2."""

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest
import yaml
from mcap.reader import make_reader

from rrtq_bringup.bench.sweep import SweepError, apply, configurations, label, parse_setting

ROOT = pathlib.Path(__file__).resolve().parents[1]
RRTQ = str(ROOT / 'scripts/rrtq')

# An 8 x 8 m square and a 4 m route: the goal in ~8 s of sim time, a few s of wall.
TINY = """
name: bench-tiny
bounds: {x: [-4, 4], y: [-4, 4]}
start: [-1.5, -1.5]
goal: [1.5, 1.5]
duration: 12.0
perception_radius: 4.0
robot_radius: 0.3
plant: {model: rover, mass: 40.0, stiffness: 20.0, damping: 45.0, spring_anchor: leg_target}
controller: {variant: nominal, horizon: 10.0, dt: 0.05, M: 10.0, R: 2.0, P_T: 0.5,
             alpha_c: 90.0, alpha_a: 1.2, rho: 0.15, probing_std: 2.0}
planner: {steer_distance: 3.0, iterations_per_step: 15, max_nodes: 600}
obstacles:
  - {id: replaced, polygon: [[-1, -1], [1, -1], [1, 1], [-1, 1]]}
"""

# The head: a Ray instance whose servers listen on 127.0.0.1 only (the variable makes
# Ray take the loopback address as the node's), two CPUs, shut down when stdin closes.
HEAD = """
import logging, sys
import ray
info = ray.init(address='local', num_cpus=2, include_dashboard=False, log_to_driver=False,
                logging_level=logging.WARNING)
print(info.address_info['gcs_address'], flush=True)
sys.stdin.read()
ray.shutdown()
"""


def bench(*args, timeout=150, **kwargs):
    return subprocess.run([RRTQ, 'bench', *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, **kwargs)


def odom(run_dir: pathlib.Path) -> list[bytes]:
    with open(run_dir / 'run.mcap', 'rb') as f:
        return [m.data for _, _, m in make_reader(f).iter_messages(topics=['/odom'])]


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / 'tiny.yaml'
    path.write_text(TINY)
    return path


@pytest.fixture(scope='module')
def ray_head():
    env = {**os.environ, 'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0'}
    head = subprocess.Popen([sys.executable, '-c', HEAD], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            env=env)
    try:
        address = head.stdout.readline().strip()
        assert address.startswith('127.0.0.1:'), address
        yield address
    finally:
        head.stdin.close()
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait()


def test_ray_engine_gives_the_local_engines_runs(tmp_path, tiny, ray_head):
    common = (tiny, '--seeds', 2, '--obstacles', 2, '--workers', 2)
    local = bench(*common, '--runs', tmp_path / 'local')
    assert local.returncode == 0, local.stderr
    on_ray = bench(*common, '--engine', 'ray', '--address', ray_head, '--runs', tmp_path / 'ray')
    assert on_ray.returncode == 0, on_ray.stderr
    table = json.loads((tmp_path / 'ray' / 'monte_carlo.json').read_text())
    assert table['engine'].startswith(f'ray ({ray_head}') and table['stats']['completed'] == 2
    for seed in (0, 1):
        a, b = (tmp_path / side / f'seed-{seed:03d}' for side in ('local', 'ray'))
        sa, sb = (json.loads((d / 'summary.json').read_text()) for d in (a, b))
        assert (sb['outcome'], sb['time_to_goal_s'], sb['path_length_m']) == \
            (sa['outcome'], sa['time_to_goal_s'], sa['path_length_m'])
        # The recording came back to the driver's runs directory, byte for byte the run's.
        assert sb['recording'] == str(b / 'run.mcap')
        assert odom(a) == odom(b) and len(odom(a)) > 100


def _run_processes(marker: str) -> list[tuple[int, int]]:
    """(pid, parent pid) of the `rrtq run` processes whose command line holds ``marker``."""
    found = []
    for proc in pathlib.Path('/proc').iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / 'cmdline').read_bytes().split(b'\0')
            stat = (proc / 'stat').read_text()
        except OSError:
            continue
        if b'rrtq_bringup.cli' in cmd and any(b'/rrtq-bench/' in c and marker.encode() in c
                                              for c in cmd):
            found.append((int(proc.name), int(stat.rsplit(')', 1)[1].split()[1])))
    return found


def test_a_killed_ray_worker_fails_only_its_run_which_is_retried(tmp_path, tiny, ray_head):
    runs = tmp_path / 'runs'
    proc = subprocess.Popen([RRTQ, 'bench', str(tiny), '--seeds', '2', '--obstacles', '2',
                             '--engine', 'ray', '--address', ray_head, '--runs', str(runs)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 90
    victims: list[tuple[int, int]] = []
    while not victims and time.monotonic() < deadline and proc.poll() is None:
        victims = _run_processes('-seed-000/scenario.yaml')   # seed 0's task on the worker
        time.sleep(0.2)
    assert victims, 'seed 0 never started on the Ray worker'
    _, worker = victims[0]
    os.kill(worker, signal.SIGKILL)            # the Ray worker running seed 0's task
    _, err = proc.communicate(timeout=150)
    assert proc.returncode == 0, err
    table = json.loads((runs / 'monte_carlo.json').read_text())
    rows = {r['seed']: r for r in table['runs']}
    assert rows[0]['attempts'] == 2 and 'Worker' in rows[0]['retried_after']
    assert rows[1]['attempts'] == 1 and rows[1]['retried_after'] is None
    assert table['stats']['completed'] == 2            # the retry completed the run
    assert rows[0]['outcome'] == json.loads((runs / 'seed-000' / 'summary.json')
                                            .read_text())['outcome']
    md = (runs / 'monte_carlo.md').read_text()
    assert 'retried once' in md and '| 0 |' in md


def test_set_values_and_cross_product():
    settings = [parse_setting('controller.R=0.02,2'),
                parse_setting('planner.steer_distance=2,3,[4]')]
    assert settings[0].values == (0.02, 2) and settings[1].values == (2, 3, [4])
    confs = configurations(settings)
    assert confs == [{'controller.R': r, 'planner.steer_distance': d}
                     for r in (0.02, 2) for d in (2, 3, [4])]
    assert label(confs[1]) == 'controller.R=0.02, planner.steer_distance=3'
    doc = apply({'controller': {'R': 1.0, 'M': 5.0}}, {'controller.R': 0.5, 'safety.margin': 'x'})
    assert doc == {'controller': {'R': 0.5, 'M': 5.0}, 'safety': {'margin': 'x'}}
    for bad in ('controller.R', 'controller.R=', '=1,2', 'seed=1,2', 'a..b=1'):
        with pytest.raises(SweepError):
            parse_setting(bad)
    with pytest.raises(SweepError):
        configurations([settings[0], settings[0]])


def test_sweep_runs_each_configuration_and_tables_it(tmp_path, tiny):
    runs, out = tmp_path / 'runs', tmp_path / 'out'
    proc = bench(tiny, '--seeds', 1, '--first-seed', 3, '--obstacles', 2, '--workers', 2,
                 '--set', 'planner.iterations_per_step=10,20', '--runs', runs, '--out', out)
    assert proc.returncode == 0, proc.stderr
    table = json.loads((out / 'sweep.json').read_text())
    confs = table['configurations']
    assert [c['label'] for c in confs] == ['planner.iterations_per_step=10',
                                           'planner.iterations_per_step=20']
    for index, conf in enumerate(confs):
        run = runs / f'cfg-{index:02d}' / 'seed-003'
        written = yaml.safe_load((run / 'scenario.yaml').read_text())
        assert written['planner']['iterations_per_step'] == (10, 20)[index]
        summary = json.loads((run / 'summary.json').read_text())
        assert conf['stats']['runs'] == 1 and conf['runs'][0]['outcome'] == summary['outcome']
        assert conf['stats']['success_rate'] == float(summary['success'])
    # Both configurations got seed 3's layout.
    a, b = (yaml.safe_load((runs / f'cfg-0{i}' / 'seed-003' / 'scenario.yaml').read_text())
            for i in (0, 1))
    assert a['obstacles'] == b['obstacles']
    md = (out / 'sweep.md').read_text()
    assert md.count('| planner.iterations_per_step=') == 2
    assert (out / 'sweep.png').stat().st_size > 10_000


@pytest.mark.parametrize('setting, named', [
    ('controller.bogus=1,2', 'controller.bogus'),
    ('controller.R=0.5,-1', 'controller.R'),
    ('plant=1,2', 'plant'),
])
def test_set_with_a_bad_key_or_value_exits_2_naming_it(tmp_path, tiny, setting, named):
    proc = bench(tiny, '--set', setting, '--runs', tmp_path / 'runs', timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert f'{tiny}: {named}' in proc.stderr and '--set' in proc.stderr, proc.stderr
    assert not (tmp_path / 'runs').exists()
