#!/usr/bin/env python3
"""Model mismatch in the node graph: ``scenarios/vf_lpc_mismatch.yaml`` with the GP and without.

The model identified on the 40 kg rover (``scenarios/models/rover_40kg.npz``, from
``scenarios/probe_rover.yaml`` by ``rrtq identify``) drives a 70 kg rover under a constant
push, through the whole graph (``rrtq run``, composed, lock-step): once with
``controller.vf_lpc.compensate: true``, once ``false``. Everything reported comes from the
recordings (``rrtq report``): outcome, time to goal, clearance, tracking error to the
guidance reference, one-step velocity prediction error of the nominal and the learned
model, the GP's 2σ coverage, the largest command, the controller's step time. Usage::

    .venv/bin/python benchmarks/vf_lpc_graph_mismatch.py
"""

from __future__ import annotations

import json
import pathlib
import subprocess
import sys
import tempfile

import yaml
from common import ROOT, save

from rrtq_bringup.report import report
from rrtq_bringup.run_data import read_run

SCENARIO = ROOT / 'scenarios' / 'vf_lpc_mismatch.yaml'


def run(compensate: bool, where: pathlib.Path) -> dict:
    data = yaml.safe_load(SCENARIO.read_text())
    data['controller']['model'] = str(ROOT / 'scenarios' / data['controller']['model'])
    data['controller']['vf_lpc']['compensate'] = compensate
    path = where / f'mismatch-{compensate}.yaml'
    path.write_text(yaml.safe_dump(data))
    out = where / f'run-{compensate}'
    proc = subprocess.run([str(ROOT / 'scripts' / 'rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True)
    live = json.loads((out / 'summary.json').read_text())
    summary = report(out / 'run.mcap')
    commands = read_run(out / 'run.mcap').cmd_u
    return {'compensate': compensate, 'exit_code': proc.returncode, 'outcome': live['outcome'],
            'time_to_goal_s': live['time_to_goal_s'], 'min_clearance_m': live['min_clearance_m'],
            'max_abs_command_N': float(abs(commands).max()),
            'controller_step_ms': live['controller_step_ms'], **summary['vf_lpc']}


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        rows = [run(comp, pathlib.Path(tmp)) for comp in (True, False)]
    table = ['| GP | outcome | time to goal s | min clearance m | tracking mean / p95 / max m '
             '| one-step v RMSE nominal → learned m/s | reduction | 2σ coverage (v_x, v_y) '
             '| max |u| N | step ms median / p95 |', '|' + '---|' * 10]
    for r in rows:
        cov = r.get('gp_2sigma_coverage', [float('nan')] * 2)
        table.append(
            f"| {'on' if r['compensate'] else 'off'} | {r['outcome']} | {r['time_to_goal_s']} "
            f"| {r['min_clearance_m']:.2f} | {r['tracking_mean_m']:.3f} / "
            f"{r['tracking_p95_m']:.3f} / {r['tracking_max_m']:.3f} "
            f"| {r['velocity_rmse_nominal']:.4f} → {r['velocity_rmse_learned']:.4f} "
            f"| {100 * r['prediction_error_reduction']:.0f} % | {cov[0]:.3f}, {cov[1]:.3f} "
            f"| {r['max_abs_command_N']:.0f} | {r['controller_step_ms']['median']:.1f} / "
            f"{r['controller_step_ms']['p95']:.1f} |")
    text = ('In the graph: identified at 40 kg, run at 70 kg under a constant push '
            '(`scenarios/vf_lpc_mismatch.yaml`), GP on and off; from the recordings. Without '
            'the GP the "learned" model is the nominal one (reduction 0, no band).\n\n'
            + '\n'.join(table))
    save('vf_lpc_graph_mismatch', {'runs': rows}, text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
