#!/usr/bin/env python3
"""``rrtq robot`` against ``rrtq plant`` at 1 x real time: the control period's jitter.

Two OS processes in one ROS domain, as a user runs them in two shells: the plant (simulator,
injector, spawner, paced at real time, publishing /clock) and the robot side (planner,
controller on its own Δt timer, safety, recorder). Run once on the machine as it is and once
with two busy processes (``while True: pass``) loading its cores. From the robot's recording:
the time between the controller's commands as the recorder received them (median, p99, max
against Δt), the stale-odometry events the controller reported on /controller/state, and
the run's outcome.

Usage: ``.venv/bin/python benchmarks/robot_plant_jitter.py [SCENARIO] [--busy 2]``; writes
``benchmarks/results/robot_plant_jitter.{json,md}``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from common import ROOT, save
from rrtq_bringup.orchestrator import domain_id

RRTQ = str(ROOT / 'scripts' / 'rrtq')


def start(args: list[str], env: dict[str, str], log) -> subprocess.Popen:
    """``rrtq ARGS`` in its own process group."""
    return subprocess.Popen([RRTQ, *args], env=env, stdout=log, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, start_new_session=True)


def stop(proc: subprocess.Popen) -> None:
    """End a process group this script started."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


def wait_for_text(path: pathlib.Path, text: str, proc: subprocess.Popen, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in path.read_text(errors='replace'):
            return
        if proc.poll() is not None:
            raise SystemExit(f'{path}: the process ended:\n' + path.read_text(errors='replace'))
        time.sleep(0.1)
    raise SystemExit(f'{path}: no {text!r} within {timeout} s')


def measure(recording: pathlib.Path, dt: float) -> dict:
    """Command periods (recorder's receive times) and the controller's stale events."""
    times, stale = [], 0
    with open(recording, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages(
                topics=['/cmd_force', '/controller/state']):
            if channel.topic == '/cmd_force':
                times.append(message.log_time * 1e-9)
            elif msg.policy_event.startswith('stale_odometry'):
                stale += 1
    period = np.diff(np.sort(np.asarray(times)))
    return {'commands': len(times), 'stale_odometry_events': stale,
            'period_ms': {'median': 1e3 * float(np.median(period)),
                          'p99': 1e3 * float(np.percentile(period, 99)),
                          'max': 1e3 * float(period.max()), 'dt': 1e3 * dt},
            'late_over_3dt': int(np.sum(period > 3 * dt))}


def run_pair(scenario: pathlib.Path, busy: int, work: pathlib.Path) -> dict:
    """Plant and robot on ``scenario`` at real time, ``busy`` spinning processes beside."""
    spinners = [subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                                 start_new_session=True) for _ in range(busy)]
    out = work / f'robot-busy{busy}'
    try:
        with domain_id() as domain:
            env = {**os.environ, 'ROS_DOMAIN_ID': str(domain),
                   'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
            plant_log, robot_log = work / f'plant-{busy}.log', work / f'robot-{busy}.log'
            with open(plant_log, 'w') as plog, open(robot_log, 'w') as rlog:
                plant = start(['plant', str(scenario), '--speed', '1'], env, plog)
                robot = None
                try:
                    wait_for_text(plant_log, 'waiting for a /cmd_force publisher', plant, 60)
                    robot = start(['robot', str(scenario), '--out', str(out), '--overwrite'],
                                  env, rlog)
                    robot.wait(timeout=1800)
                finally:
                    for proc in (robot, plant):
                        if proc is not None:
                            stop(proc)
    finally:
        for s in spinners:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(s.pid, signal.SIGKILL)
            s.wait()
    summary = json.loads((out / 'summary.json').read_text())
    dt = 0.05
    return {'busy': busy, 'outcome': summary['outcome'], 'reason': summary.get('reason'),
            'exit_code': robot.returncode if robot is not None else None,
            **measure(out / 'run.mcap', dt)}


def render(scenario: str, rows: list[dict]) -> str:
    lines = [f'`rrtq plant {scenario} --speed 1` and `rrtq robot {scenario}` in two processes '
             '(one ROS domain, loopback); the controller on its own Δt = 50 ms timer. Periods: '
             'time between the controller\'s commands as the recorder received them.', '',
             '| machine load | outcome | commands | period median ms | p99 ms | max ms | '
             'periods > 3 Δt | stale-odometry events |', '|---|---|---|---|---|---|---|---|']
    for r in rows:
        p = r['period_ms']
        load = 'as it is' if r['busy'] == 0 else f"{r['busy']} busy processes"
        lines.append(f"| {load} | {r['outcome']} | {r['commands']} | {p['median']:.1f} | "
                     f"{p['p99']:.1f} | {p['max']:.1f} | {r['late_over_3dt']} | "
                     f"{r['stale_odometry_events']} |")
    return '\n'.join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('scenario', nargs='?', type=pathlib.Path,
                    default=ROOT / 'scenarios' / 'defaults_only.yaml')
    ap.add_argument('--busy', type=int, default=2, help='busy processes in the loaded run')
    ap.add_argument('--no-save', action='store_true')
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix='rrtq-jitter-') as tmp:
        for busy in (0, args.busy):
            print(f'robot_plant_jitter: {busy} busy processes', file=sys.stderr, flush=True)
            rows.append(run_pair(args.scenario.resolve(), busy, pathlib.Path(tmp)))
    name = str(args.scenario.resolve().relative_to(ROOT)) if args.scenario.resolve().is_relative_to(
        ROOT) else str(args.scenario)
    table = render(name, rows)
    if args.no_save:
        print(table)
    else:
        save('robot_plant_jitter', {'scenario': name, 'rows': rows}, table)
    return 0


if __name__ == '__main__':
    sys.exit(main())
