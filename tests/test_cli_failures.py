"""Bad input exits 2 before anything starts; crashes and kills end runs cleanly."""

import contextlib
import io
import json
import os
import pathlib
import signal
import subprocess
import time

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.records import Message

from rrtq_bringup.orchestrator import DOMAIN_LOCK_DIR

ROOT = pathlib.Path(__file__).resolve().parents[1]
RRTQ = str(ROOT / 'scripts/rrtq')

GOOD = """
name: cli
bounds: {x: [-20, 20], y: [-20, 20]}
start: [-5.0, -5.0]
goal: [10.0, 10.0]
duration: 600.0
plant: {model: rover, stiffness: 0.0}
controller: {variant: open_loop, forces: [[0.0, 5.0, 5.0]]}
obstacles:
  - {id: box, polygon: [[0, 0], [2, 0], [2, 2], [0, 2]]}
"""

BAD = {
    'unknown key': (GOOD.replace('duration: 600.0', 'duration: 600.0\nspeeed: 3'), 'speeed'),
    'wrong shape': (GOOD.replace('[[0, 0], [2, 0], [2, 2], [0, 2]]', '[[0, 0], [2, 0]]'),
                    'obstacles[0].polygon'),
    'start inside an obstacle': (GOOD.replace('start: [-5.0, -5.0]', 'start: [1.0, 1.0]'),
                                 'start'),
    'goal inside an obstacle': (GOOD.replace('goal: [10.0, 10.0]', 'goal: [1.0, 1.5]'),
                                'goal'),
    'goal outside the bounds': (GOOD.replace('goal: [10.0, 10.0]', 'goal: [30.0, 10.0]'),
                                'goal'),
    'bad enum value': (GOOD.replace('model: rover', 'model: tank'), 'plant.model'),
    'negative mass': (GOOD.replace('stiffness: 0.0}', 'stiffness: 0.0, mass: -1}'),
                      'plant.mass'),
    'actuation delay off the step': (GOOD.replace('stiffness: 0.0}',
                                                  'stiffness: 0.0, actuation_delay: 0.12}'),
                                     'plant.actuation_delay'),
    'negative odometry noise': (GOOD.replace('stiffness: 0.0}', 'stiffness: 0.0, '
                                             'odometry_noise: {position: -0.01}}'),
                                'plant.odometry_noise.position'),
    'YAML syntax error': (GOOD.replace('goal: [10.0, 10.0]', 'goal: [10.0, 10.0'), ''),
    'robust without gamma': (GOOD.replace('{variant: open_loop, forces: [[0.0, 5.0, 5.0]]}',
                                          '{variant: robust}'), 'controller.gamma'),
    'unknown planner key': (GOOD.replace('duration: 600.0', 'duration: 600.0\nplanner: {delta: 2}'),
                            'planner.delta'),
    'missing calibration file': (GOOD.replace('duration: 600.0', 'duration: 600.0\nsafety: '
                                              '{margin: conformal, calibration: gone.json}'),
                                 'safety.calibration'),
}


@pytest.mark.parametrize('kind', sorted(BAD))
def test_bad_scenario_exits_2_naming_file_and_key(tmp_path, kind):
    text, key = BAD[kind]
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    out = tmp_path / 'out'
    proc = subprocess.run([RRTQ, 'run', str(path), '--out', str(out)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert str(path) in proc.stderr and key in proc.stderr
    assert not out.exists()            # nothing started, nothing written


def test_corrupt_model_file_exits_2_naming_file_and_key(tmp_path):
    # A truncated .npz (zip magic, no central directory) used to end in a BadZipFile
    # traceback with exit 1; it is bad input like any other.
    buf = io.BytesIO()
    np.savez(buf, A=np.eye(4))
    (tmp_path / 'model.npz').write_bytes(buf.getvalue()[:60])
    path = tmp_path / 'bad.yaml'
    path.write_text(GOOD.replace('{variant: open_loop, forces: [[0.0, 5.0, 5.0]]}',
                                 '{variant: nominal, model: model.npz}'))
    out = tmp_path / 'out'
    proc = subprocess.run([RRTQ, 'run', str(path), '--out', str(out)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert str(path) in proc.stderr and 'controller.model' in proc.stderr
    assert str(tmp_path / 'model.npz') in proc.stderr and 'Traceback' not in proc.stderr
    assert not out.exists()


def test_missing_file_and_bad_speed_exit_2(tmp_path):
    missing = subprocess.run([RRTQ, 'run', str(tmp_path / 'nope.yaml')], capture_output=True,
                             text=True, timeout=60)
    assert missing.returncode == 2 and 'nope.yaml' in missing.stderr
    path = tmp_path / 'ok.yaml'
    path.write_text(GOOD)
    speed = subprocess.run([RRTQ, 'run', str(path), '--speed', 'fast'], capture_output=True,
                           text=True, timeout=60)
    assert speed.returncode == 2 and '--speed' in speed.stderr


def test_existing_recording_is_not_overwritten(tmp_path):
    path = tmp_path / 'ok.yaml'
    path.write_text(GOOD)
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'run.mcap').write_bytes(b'precious')
    proc = subprocess.run([RRTQ, 'run', str(path), '--out', str(out)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and '--overwrite' in proc.stderr
    assert (out / 'run.mcap').read_bytes() == b'precious'


def children_of(pid):
    """Direct children of ``pid`` (from /proc)."""
    kids = []
    for stat in pathlib.Path('/proc').glob('[0-9]*/stat'):
        try:
            fields = stat.read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def cmdline(pid):
    try:
        return pathlib.Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ').decode()
    except OSError:
        return ''


def alive(pid):
    try:
        state = pathlib.Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'


def start_paced_run(tmp_path):
    path = tmp_path / 'long.yaml'
    path.write_text(GOOD)
    out = tmp_path / 'out'
    proc = subprocess.Popen([RRTQ, 'run', str(path), '--out', str(out), '--speed', '1.0'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        kids = children_of(proc.pid)
        mcap = out / 'run.mcap'
        # simulator, controller, disturbance injector, spawner, recorder, viz (open loop)
        if len(kids) == 6 and mcap.exists() and mcap.stat().st_size > 20_000:
            return proc, out, kids
        time.sleep(0.2)
    proc.kill()
    raise AssertionError('the run did not get going within 60 s')


def wait_gone(pids, timeout=15.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(alive(p) for p in pids):
        time.sleep(0.1)
    return [p for p in pids if alive(p)]


def test_crashed_node_fails_the_run_naming_it(tmp_path):
    proc, out, kids = start_paced_run(tmp_path)
    controller = next(p for p in kids if 'controller_node' in cmdline(p))
    os.kill(controller, signal.SIGKILL)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 1
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['outcome'] == 'node_failed'
    assert summary['failed_node']['node'] == 'controller'
    assert 'SIGKILL' in summary['failed_node']['status'] and "'controller'" in stderr
    assert wait_gone(kids) == []
    reader = make_reader(open(out / 'run.mcap', 'rb'))
    assert reader.get_summary().statistics.channel_message_counts   # finished and readable


def open_files(pid):
    found = set()
    for fd in pathlib.Path(f'/proc/{pid}/fd').iterdir():
        with contextlib.suppress(OSError):
            found.add(os.readlink(fd))
    return found


def test_sigkill_of_orchestrator_leaves_no_orphans_and_a_finished_recording(tmp_path):
    proc, out, kids = start_paced_run(tmp_path)
    # Every node holds the run's domain lock: the domain is not free while one of them
    # tears down (a later run would see it).
    domain = dict(line.split('=', 1) for line in pathlib.Path(f'/proc/{kids[0]}/environ')
                  .read_bytes().decode().split('\0') if '=' in line)['ROS_DOMAIN_ID']
    lock = str(DOMAIN_LOCK_DIR / f'{domain}.lock')
    assert all(lock in open_files(pid) for pid in kids), [cmdline(p) for p in kids]
    proc.kill()
    proc.wait()
    assert wait_gone(kids) == [], [cmdline(p) for p in kids]
    reader = make_reader(open(out / 'run.mcap', 'rb'))
    assert reader.get_summary().statistics.message_count > 0


def test_sigkill_of_everything_leaves_a_readable_recording(tmp_path):
    proc, out, kids = start_paced_run(tmp_path)
    time.sleep(1.5)                    # at least one more chunk closed by the flush period
    for pid in [proc.pid, *kids]:
        os.kill(pid, signal.SIGKILL)
    proc.wait()
    assert wait_gone(kids) == []
    odom = 0
    with open(out / 'run.mcap', 'rb') as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Message):
                    odom += 1
        except Exception:              # the torn tail after the last complete chunk
            pass
    assert odom > 20


@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_the_run_cleanly(tmp_path, sig):
    proc, out, kids = start_paced_run(tmp_path)
    proc.send_signal(sig)
    proc.communicate(timeout=60)
    assert proc.returncode == 1
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['outcome'] == 'interrupted' and sig.name in summary['reason']
    assert wait_gone(kids) == []
    reader = make_reader(open(out / 'run.mcap', 'rb'))
    assert reader.get_summary().statistics.channel_message_counts
