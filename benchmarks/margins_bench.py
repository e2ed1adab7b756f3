"""The three margin modes in the closed loop, from an ``rrtq bench --set safety.margin=...`` sweep.

Reads each run's recording (``RUNS/cfg-NN/seed-NNN/run.mcap``) and summary: outcome, time to
goal, path / optimum (the bench's layout optimum), the mean margin over the run (m, robot
radius excluded), and the legs whose largest deviation exceeded the margin in force at
their start (``/safety/status.violations``), as a rate against δ with its 95 %
Clopper-Pearson interval over all the mode's legs. The coverage columns are the
recording-only check (:mod:`rrtq_bringup.margin_coverage`): each leg's deviation recomputed
from ``/odom`` and the controller's leg, against the least margin published while it ran.

    python benchmarks/margins_bench.py NAME RUNS [RUNS ...]

writes ``benchmarks/results/NAME.{md,json}``.
"""

from __future__ import annotations

import json
import pathlib
import sys

import numpy as np
import yaml

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

from common import save  # noqa: E402
from rrtq_bringup.margin_coverage import coverage  # noqa: E402
from rrtq_bringup.run_data import messages  # noqa: E402
from rrtq_planner.margins.coverage import binomial_interval  # noqa: E402


def statuses(recording: pathlib.Path) -> list:
    return messages(recording, '/safety/status')


def run_row(seed_dir: pathlib.Path) -> dict:
    summary = json.loads((seed_dir / 'summary.json').read_text())
    layout = json.loads((seed_dir / 'layout.json').read_text())
    status = statuses(seed_dir / 'run.mcap')
    radius = float(yaml.safe_load((seed_dir / 'scenario.yaml').read_text())
                   .get('robot_radius', 0.0))
    last = status[-1]
    margins = np.array([s.margin for s in status]) - radius
    checked = coverage([seed_dir / 'run.mcap'])
    return {'seed': seed_dir.name, 'mode': last.margin_mode, 'outcome': summary['outcome'],
            'success': bool(summary['success']), 'collided': bool(summary['collided']),
            'time_to_goal_s': summary.get('time_to_goal_s'),
            'path_over_optimum': (summary['path_length_m'] / layout['optimum_m']
                                  if summary['success'] else None),
            'mean_margin_m': float(margins.mean()), 'max_margin_m': float(margins.max()),
            'd_rob_max_m': float(last.d_rob_max), 'legs': int(last.legs),
            'violations': int(last.violations), 'confidence': float(last.confidence),
            'checked_legs': len(checked.legs), 'checked_misses': checked.misses}


def table(rows: list[dict]) -> str:
    lines = ['| mode | runs | goal | collisions | path / optimum (median) | mean margin (m) | '
             'max D_rob (m) | legs | violations | rate [95 % interval] | '
             'recording check: misses / legs, rate [95 %] |',
             '|---|---|---|---|---|---|---|---|---|---|---|']
    for mode in dict.fromkeys(r['mode'] for r in rows):
        rs = [r for r in rows if r['mode'] == mode]
        legs, bad = sum(r['legs'] for r in rs), sum(r['violations'] for r in rs)
        lo, hi = binomial_interval(bad, legs) if legs else (float('nan'),) * 2
        ratios = [r['path_over_optimum'] for r in rs if r['path_over_optimum'] is not None]
        ratio = f'{np.median(ratios):.2f}' if ratios else '—'
        # running_max predicts nothing before a leg (its margin is the maximum so far):
        # it counts no violations.
        rate = (f'{bad / max(legs, 1):.3f} [{lo:.3f}, {hi:.3f}]' if mode != 'running_max'
                else 'not counted')
        cl, cb = sum(r['checked_legs'] for r in rs), sum(r['checked_misses'] for r in rs)
        clo, chi = binomial_interval(cb, cl) if cl else (float('nan'),) * 2
        check = f'{cb}/{cl}, {cb / max(cl, 1):.3f} [{clo:.3f}, {chi:.3f}]'
        lines.append(
            f"| {mode} | {len(rs)} | {sum(r['success'] for r in rs)}/{len(rs)} | "
            f"{sum(r['collided'] for r in rs)} | {ratio} | "
            f"{np.mean([r['mean_margin_m'] for r in rs]):.2f} | "
            f"{max(r['d_rob_max_m'] for r in rs):.2f} | {legs} | {bad} | {rate} | {check} |")
    return '\n'.join(lines)


def _time(t: float | None) -> str:
    return '—' if t is None else f'{t:.2f}'


def main() -> None:
    name, runs = sys.argv[1], [pathlib.Path(p) for p in sys.argv[2:]]
    rows = [run_row(d) for r in runs for d in sorted(r.glob('cfg-*/seed-*'))
            if (d / 'summary.json').exists()]
    text = table(rows) + '\n\nPer run:\n\n| mode | seed | outcome | time to goal (s) | ' \
        'mean margin (m) | legs | violations |\n|---|---|---|---|---|---|---|\n' + '\n'.join(
            f"| {r['mode']} | {r['seed']} | {r['outcome']} | {_time(r['time_to_goal_s'])} | "
            f"{r['mean_margin_m']:.2f} | {r['legs']} | {r['violations']} |" for r in rows)
    save(name, {'runs': [str(r) for r in runs], 'rows': rows}, text)


if __name__ == '__main__':
    main()
