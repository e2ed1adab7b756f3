#!/usr/bin/env python3
"""VF-LPC side by side with RRT-QX: the table of a ``--set controller.variant=...`` sweep.

Runs (or, with ``--read-only``, only reads the runs of) ``scripts/rrtq bench
scenarios/vf_lpc_bench.yaml --seeds 3 --workers 1 --set controller.variant=nominal,vf_lpc``

and writes ``results/vf_lpc_bench.md`` / ``.json``: per configuration, over the same seeds
and random layouts, success and collisions, time to goal, path length, control effort
(Σ‖u‖²Δt), the largest lateral acceleration v²κ and jerk of the driven path (from
``/odom``, :func:`rrtq_bringup.report.vf_lpc.lateral_acceleration`) and of the published
references (every sample of every ``/guidance/reference``, vf_lpc only), the smallest
clearance to the true obstacles, and the controller's wall time per step (the run's
``step_ms``; the machine is shared). Usage::

    .venv/bin/python benchmarks/vf_lpc_bench.py [--runs RUNS] [--seeds N]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys

import numpy as np
from common import ROOT, save
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rrtq_bringup.report.vf_lpc import lateral_acceleration
from rrtq_bringup.run_data import read_run

SCENARIO = ROOT / 'scenarios' / 'vf_lpc_bench.yaml'


def reference_lateral(mcap: pathlib.Path) -> np.ndarray:
    """v²κ at every moving interior sample of every /guidance/reference.

    κ the circumradius curvature of three consecutive samples, v the chord's speed (the
    measure of the guidance tests and of docs/vf_lpc.md §1.5).
    """
    out = []
    with mcap.open('rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, _, msg in reader.iter_decoded_messages(topics=['/guidance/reference']):
            p = np.array([[q.x, q.y] for q in msg.positions]).reshape(-1, 2)
            if len(p) < 3:
                continue
            u, w = p[1:-1] - p[:-2], p[2:] - p[1:-1]
            c = np.linalg.norm(p[2:] - p[:-2], axis=1)
            den = np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1) * c
            cross = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
            with np.errstate(divide='ignore', invalid='ignore'):
                kappa = np.where(den > 0.0, 2.0 * cross / den, 0.0)
            speed = c / (2.0 * msg.dt)
            out.append((speed ** 2 * kappa)[speed > 0.1])
    return np.concatenate(out) if out else np.zeros(0)


def row(run: pathlib.Path) -> dict:
    s = json.loads((run / 'summary.json').read_text())
    data = read_run(run / 'run.mcap')
    lateral, jerk = lateral_acceleration(data.odom_t, data.odom_x)
    ref = reference_lateral(run / 'run.mcap')
    return {'seed': run.name, 'outcome': s['outcome'], 'success': s['success'],
            'collided': s['collided'], 'time_to_goal_s': s['time_to_goal_s'],
            'path_length_m': s['path_length_m'], 'control_effort': s['control_effort'],
            'lateral_max': float(lateral.max()) if lateral.size else float('nan'),
            'lateral_within_2': float(np.mean(lateral <= 2.0)) if lateral.size else float('nan'),
            'lateral_count': int(lateral.size), 'reference_count': int(ref.size),
            'reference_max': float(ref.max()) if ref.size else float('nan'),
            'reference_within_2': float(np.mean(ref <= 2.0)) if ref.size else float('nan'),
            'jerk_max': float(jerk.max()) if jerk.size else float('nan'),
            'min_clearance_m': s['min_clearance_m'],
            'step_ms_median': s['controller_step_ms']['median'],
            'step_ms_p95': s['controller_step_ms']['p95']}


def med(rows: list[dict], key: str) -> float:
    values = [r[key] for r in rows if r[key] is not None]
    return float(np.median(values)) if values else float('nan')


def share(rows: list[dict], key: str) -> str:
    """'max (worst run's share, pooled share)' of v²κ, or a dash without samples."""
    rows = [r for r in rows if r[f'{key}_count']]
    if not rows:
        return '—'
    pooled = (sum(r[f'{key}_within_2'] * r[f'{key}_count'] for r in rows)
              / sum(r[f'{key}_count'] for r in rows))
    return (f"{max(r[f'{key}_max'] for r in rows):.2f} "
            f"({min(r[f'{key}_within_2'] for r in rows):.3f}, {pooled:.4f})")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--runs', type=pathlib.Path, default=ROOT / 'runs' / 'bench-vflpc')
    parser.add_argument('--seeds', type=int, default=8)
    parser.add_argument('--read-only', action='store_true', help='table of a finished sweep')
    args = parser.parse_args()
    if not args.read_only:
        subprocess.run([str(ROOT / 'scripts' / 'rrtq'), 'bench', str(SCENARIO), '--seeds',
                        str(args.seeds), '--workers', '1', '--set',
                        'controller.variant=nominal,vf_lpc', '--runs', str(args.runs),
                        '--out', str(args.runs), '--overwrite'], check=True)
    configs = {}
    for cfg, variant in (('cfg-00', 'nominal (RRT-QX)'), ('cfg-01', 'vf_lpc')):
        configs[variant] = [row(r) for r in sorted((args.runs / cfg).glob('seed-*'))
                            if (r / 'summary.json').is_file()]
    lines = ['| controller | runs | goal | collisions | time to goal s | path m | effort N²s '
             '| driven max v²κ m/s² (share ≤ 2: worst run, all) '
             '| reference max v²κ (share ≤ 2: worst run, all) | max jerk m/s³ '
             '| min clearance m | step ms median / p95 |', '|' + '---|' * 12]
    for variant, rows in configs.items():
        ok = [r for r in rows if r['success']]
        lines.append(
            f"| {variant} | {len(rows)} | {len(ok)} | {sum(r['collided'] for r in rows)} "
            f"| {med(ok, 'time_to_goal_s'):.1f} | {med(ok, 'path_length_m'):.1f} "
            f"| {med(rows, 'control_effort'):.3g} | {share(rows, 'lateral')} "
            f"| {share(rows, 'reference') if variant == 'vf_lpc' else '—'} "
            f"| {max(r['jerk_max'] for r in rows):.0f} "
            f"| {min(r['min_clearance_m'] for r in rows):.2f} "
            f"| {med(rows, 'step_ms_median'):.1f} / {med(rows, 'step_ms_p95'):.1f} |")
    text = (f'`rrtq bench {SCENARIO.relative_to(ROOT)} --seeds {args.seeds} --set '
            'controller.variant=nominal,vf_lpc` (random layouts of 8 obstacles, a quarter '
            'known, the rest appearing near the route; the same seeds and layouts for both). '
            'Medians over the runs that reached the goal (time, path), over all runs (effort, '
            'step time); max / min over all runs for v²κ, jerk and clearance. v²κ of the driven '
            'path from /odom (|v × a|/|v|, samples faster than 0.1 m/s) and of every sample of '
            'every published /guidance/reference (circumradius of three samples, chord '
            'speed; RRT-QX ignores the reference, so none for it); in brackets the share '
            '≤ a_max = 2 m/s² of the worst run and of all samples pooled. Step time is wall '
            'time on the shared machine.\n\n' + '\n'.join(lines))
    save('vf_lpc_bench', {'configurations': configs}, text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
