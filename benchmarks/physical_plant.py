#!/usr/bin/env python3
"""The robot side on a physics plant and on a laser scan, from the controller's defaults.

Two ``rrtq bench`` sweeps on the random layouts of ``rrtq bench`` (8 obstacles per seed, the
same layout for every configuration of a seed), lock-step:

* **MuJoCo plant** (``scenarios/mujoco_friction.yaml``: the 40 kg, 45 kg/s shipped base,
  ``--set plant.friction=0,0.1,0.3``, the Coulomb coefficient μ, so 0, 39 and 118 N per
  axis): goals, physical contacts (runs whose plant felt one), collisions, the last ten
  legs' cost against the Riccati policy of the linear part (mass and damping, no friction)
  flown through the same disturbance, the largest command against the limit;
* **scan against polygons** (``scenarios/defaults_only.yaml``,
  ``--set perception.source=polygons,scan``: 360 beams to the perception radius at 10 Hz,
  the robot-side ``obstacle_mapper`` building the map): goals, collisions, the smallest
  clearance (least over the runs, and the median of each run's least), path / optimum.

Usage: ``.venv/bin/python benchmarks/physical_plant.py [--seeds 20] [--friction-seeds 10]
[--workers 2] [--runs DIR]``; writes ``benchmarks/results/physical_plant.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import time

import numpy as np

from common import ROOT, rrtq_bench, save

SWEEPS = {
    'mujoco': ('scenarios/mujoco_friction.yaml', ['plant.friction=0,0.1,0.3', 'duration=300']),
    'scan': ('scenarios/defaults_only.yaml', ['perception.source=polygons,scan']),
}


def bench(name: str, seeds: int, args: argparse.Namespace) -> dict:
    """One ``rrtq bench`` sweep; its table and every run's summary."""
    base, settings = SWEEPS[name]
    out = args.runs / name
    started = time.monotonic()
    table, command = rrtq_bench(name, ROOT / base, out,
                                ['--seeds', str(seeds), '--workers', str(args.workers)], settings)
    for conf in table['configurations']:
        for run in conf['runs']:
            path = pathlib.Path(run['dir']) / 'summary.json'
            run['summary'] = json.loads(path.read_text()) if path.exists() else {}
    return {'command': command,
            'configurations': table['configurations'], 'wall_s': time.monotonic() - started}


def _goals(stats: dict) -> str:
    ci = stats['success_rate_ci95']
    text = f"{stats['successes']}/{stats['completed']}"
    return text + (f" ({100 * ci[0]:.0f}–{100 * ci[1]:.0f} %)" if ci else '')


def render(results: dict) -> str:
    lines = ['From the controller\'s defaults on the random layouts of `rrtq bench` (8 '
             'obstacles per seed, the same layouts in every row of a table), lock-step.', '',
             '**MuJoCo plant** (the shipped 40 kg, 45 kg/s base; `plant.friction` is the '
             'Coulomb coefficient μ, per axis μ m g):', '',
             '| friction μ (N per axis) | goals (95 % CI) | physical contacts | collisions | '
             'last ten / Riccati policy of the linear part: median (within 5 % / 10 %) | '
             'largest command / limit | time to goal s (median) | mission failures |',
             '|---|---|---|---|---|---|---|---|']
    for conf in results['mujoco']['configurations']:
        s, c = conf['stats'], conf['stats'].get('control') or {}
        mu = float(conf['overrides']['plant.friction'])
        contacts = sum(1 for r in conf['runs'] if r.get('summary', {}).get('contact_steps', 0))
        fails = ', '.join(sorted({f['outcome'] for f in s['mission_failures']})) or '—'
        ttg = s['time_to_goal_s']['median']
        lines.append(
            f"| {mu:g} ({mu * 40 * 9.81:.0f}) | {_goals(s)} | {contacts} | {s['collisions']} | "
            f"{c.get('ratio_riccati_policy_median', float('nan')):.3f} "
            f"({c.get('within_5pct', 0)} / {c.get('within_10pct', 0)} of {c.get('runs', 0)}) | "
            f"{c.get('max_force_over_limit', float('nan')):.3f} | "
            f"{'—' if ttg is None else f'{ttg:.1f}'} | {fails} |")
    lines += ['', '**Scan against polygons** (`perception.source`; scan: 360 beams to 8 m at '
              '10 Hz, the robot-side obstacle_mapper):', '',
              '| perception | goals (95 % CI) | collisions | smallest clearance m: least '
              '(median) | path / optimum (median / p95) | time to goal s (median) |',
              '|---|---|---|---|---|---|']
    for conf in results['scan']['configurations']:
        s = conf['stats']
        clear = [r['min_clearance_m'] for r in conf['runs']
                 if r.get('min_clearance_m') is not None]
        pop = s['path_over_optimum']
        ttg = s['time_to_goal_s']['median']
        lines.append(
            f"| {conf['overrides']['perception.source']} | {_goals(s)} | {s['collisions']} | "
            f"{min(clear):.2f} ({float(np.median(clear)):.2f}) | "
            f"{pop['median']:.3f} / {pop['p95']:.3f} | {'—' if ttg is None else f'{ttg:.1f}'} |")
    failed = [(k, conf['label'], f['seed'], f['outcome'], f['reason'])
              for k in ('mujoco', 'scan') for conf in results[k]['configurations']
              for f in conf['stats']['mission_failures']]
    if failed:
        lines += ['', 'Missions that failed:', '', '| sweep | configuration | seed | outcome | '
                  'reason |', '|---|---|---|---|---|']
        lines += [f'| {a} | {b} | {c} | {d} | {e} |' for a, b, c, d, e in failed]
    lines += ['', 'Commands:', '']
    lines += [f"- {k}: `{results[k]['command']}`" for k in ('mujoco', 'scan')]
    return '\n'.join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=20, help='seeds of the scan sweep')
    ap.add_argument('--friction-seeds', type=int, default=20, help='seeds of the MuJoCo sweep')
    ap.add_argument('--workers', type=int, default=os.cpu_count() or 1)
    ap.add_argument('--runs', type=pathlib.Path, default=ROOT / 'runs' / 'physical_plant')
    ap.add_argument('--no-save', action='store_true')
    args = ap.parse_args()
    results = {'mujoco': bench('mujoco', args.friction_seeds, args),
               'scan': bench('scan', args.seeds, args)}
    table = render(results)
    if args.no_save:
        print(table)
    else:
        for sweep in results.values():          # the per-run summaries stay in the run dirs
            for conf in sweep['configurations']:
                for run in conf['runs']:
                    run.pop('summary', None)
        save('physical_plant', {'seeds': args.seeds, 'friction_seeds': args.friction_seeds,
                                **results}, table)
    return 0


if __name__ == '__main__':
    sys.exit(main())
