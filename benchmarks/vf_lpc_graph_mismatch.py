#!/usr/bin/env python3
"""Model mismatch in the node graph: ``scenarios/vf_lpc_mismatch.yaml`` with the GP and without.

The model identified on the 40 kg rover (``scenarios/models/rover_40kg.npz``, from
``scenarios/probe_rover.yaml`` by ``rrtq identify``) drives a 70 kg rover through a
position-dependent disturbance field (four bumps of acceleration on the route), through
the whole graph (``rrtq run``, composed, lock-step): once with
``controller.vf_lpc.compensate: true``, once ``false``. Everything reported comes from the
recordings (``rrtq report``): outcome, time to goal, clearance, tracking error to the
guidance reference, one-step velocity prediction error of the nominal and the learned
model, the GP's 2σ coverage, the largest command, the controller's step time; and
``results/vf_lpc_graph_mismatch.png``: the tracking error of both runs over time, the
bumps' acceleration at the robot, and the GP run's one-step velocity errors (nominal,
learned) with the 2σ band. Usage::

    .venv/bin/python benchmarks/vf_lpc_graph_mismatch.py [--keep DIR [--read-only]]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile

import matplotlib
import numpy as np
import yaml
from common import RESULTS, ROOT, save
from vf_lpc_bench import reference_lateral

from rrtq_bringup.report.run import report
from rrtq_bringup.report.vf_lpc import plot_prediction_error, vf_lpc_series
from rrtq_bringup.run_data import read_run

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

SCENARIO = ROOT / 'scenarios' / 'vf_lpc_mismatch.yaml'


def run(compensate: bool, where: pathlib.Path) -> int:
    """One run of the scenario, GP on or off, into ``where/run-<compensate>``; exit code."""
    data = yaml.safe_load(SCENARIO.read_text())
    data['controller']['model'] = str(ROOT / 'scenarios' / data['controller']['model'])
    data['controller']['vf_lpc']['compensate'] = compensate
    path = where / f'mismatch-{compensate}.yaml'
    path.write_text(yaml.safe_dump(data))
    out = where / f'run-{compensate}'
    proc = subprocess.run([str(ROOT / 'scripts' / 'rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed', '--overwrite'], capture_output=True, text=True)
    return proc.returncode


def summarise(compensate: bool, where: pathlib.Path, exit_code: int | None) -> dict:
    """The numbers of one run, from its recording."""
    out = where / f'run-{compensate}'
    live = json.loads((out / 'summary.json').read_text())
    summary = report(out / 'run.mcap')
    commands = read_run(out / 'run.mcap').cmd_u
    ref = reference_lateral(out / 'run.mcap')
    return {'compensate': compensate, 'exit_code': exit_code, 'outcome': live['outcome'],
            'time_to_goal_s': live['time_to_goal_s'], 'min_clearance_m': live['min_clearance_m'],
            'max_abs_command_N': float(abs(commands).max()),
            'reference_lateral_max': float(ref.max()),
            'reference_within_a_max': float(np.mean(ref <= summary['vf_lpc']['a_max'])),
            'controller_step_ms': live['controller_step_ms'], **summary['vf_lpc']}


def figure(where: pathlib.Path, path: pathlib.Path) -> None:
    """Tracking error (GP on, off), the field at the robot, the GP run's velocity errors."""
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    for comp, colour in ((True, 'tab:blue'), (False, 'tab:red')):
        data = read_run(where / f'run-{comp}' / 'run.mcap')
        s = vf_lpc_series(data)
        axes[0].plot(s['t'], s['tracking'], lw=0.8, color=colour,
                     label=f"GP {'on' if comp else 'off'}")
        if comp:
            d = np.asarray(data.dist_d, dtype=float).reshape(len(data.dist_t), -1)
            axes[1].plot(data.dist_t, np.hypot(d[:, 0], d[:, 1]), lw=0.8, color='k')
            for ax, j, name in ((axes[2], 2, '$v_x$'), (axes[3], 3, '$v_y$')):
                plot_prediction_error(ax, s, j, name, 'nominal model (40 kg)')
    axes[0].set_ylabel('tracking error [m]')
    axes[0].legend(loc='upper right', fontsize=8)
    axes[1].set_ylabel('field |a(p)|\n[m/s²]')
    axes[3].set_xlabel('sim time [s]')
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle('vf_lpc in the graph: 40 kg model, 70 kg rover, disturbance field',
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--keep', type=pathlib.Path, help='keep the two runs here')
    parser.add_argument('--read-only', action='store_true',
                        help="only the table and figure of the runs kept in --keep")
    args = parser.parse_args()
    if args.read_only and args.keep is None:
        parser.error('--read-only needs --keep DIR')
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or pathlib.Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        codes = {comp: None if args.read_only else run(comp, where) for comp in (True, False)}
        rows = [summarise(comp, where, codes[comp]) for comp in (True, False)]
        figure(where, RESULTS / 'vf_lpc_graph_mismatch.png')
    table = ['| GP | outcome | time to goal s | min clearance m | tracking mean / p95 / max m '
             '| one-step v RMSE nominal → learned m/s | reduction | 2σ coverage (v_x, v_y) '
             '| driven max v²κ m/s² (share ≤ a_max) | reference max v²κ (share) | max |u| N '
             '| step ms median / p95 |', '|' + '---|' * 12]
    for r in rows:
        on = r['compensate']
        cov = r['gp_2sigma_coverage']
        table.append(
            f"| {'on' if on else 'off'} | {r['outcome']} | {r['time_to_goal_s']:.2f} "
            f"| {r['min_clearance_m']:.2f} | {r['tracking_mean_m']:.3f} / "
            f"{r['tracking_p95_m']:.3f} / {r['tracking_max_m']:.3f} "
            + (f"| {r['velocity_rmse_nominal']:.4f} → {r['velocity_rmse_learned']:.4f} "
               f"| {100 * r['prediction_error_reduction']:.0f} % | {cov[0]:.3f}, {cov[1]:.3f} "
               if on else f"| {r['velocity_rmse_nominal']:.4f} (nominal only) | — | — ")
            + f"| {r['lateral_acceleration_max']:.2f} ({r['lateral_within_a_max']:.3f}) "
            f"| {r['reference_lateral_max']:.2f} ({r['reference_within_a_max']:.4f}) "
            f"| {r['max_abs_command_N']:.0f} | {r['controller_step_ms']['median']:.1f} / "
            f"{r['controller_step_ms']['p95']:.1f} |")
    text = ('In the graph: identified at 40 kg, run at 70 kg through a disturbance field of '
            'four bumps on the route (`scenarios/vf_lpc_mismatch.yaml`), GP on and off; from '
            'the recordings; step time is wall time on the shared machine. Figure: '
            '`vf_lpc_graph_mismatch.png`.\n\n'
            + '\n'.join(table))
    save('vf_lpc_graph_mismatch', {'runs': rows}, text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
