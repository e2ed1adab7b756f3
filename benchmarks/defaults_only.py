#!/usr/bin/env python3
"""The closed loop from the controller's defaults, undisturbed, on seven plants.

Each row is one ``rrtq bench`` of ``scenarios/defaults_only.yaml`` (a random 8-obstacle
layout per seed, no controller key: no initial gain, the defaults) with its plant set by
``--set``. Per row: goals with their 95 % interval (Wilson), collisions, runs out of bounds,
time to goal, path over the layout's optimum, the last ten legs' cost against the Riccati
optimum from each leg's start (its range over the runs, and the runs within 5 %) and against
the true Riccati policy flown through the same run (``rrtq_bringup.bench.control``), and the
largest command against the actuator's limit. Targets (issue 9): every goal, no collision,
no command beyond the limit, the last ten legs within 5 % of the optimum.

Usage: ``.venv/bin/python benchmarks/defaults_only.py [--seeds 20] [--engine local|ray]
[--rows NAME ...] [--runs DIR]``; writes ``benchmarks/results/defaults_only.{json,md}``.
"""

from __future__ import annotations

import sys

from common import ROOT, failures_and_commands, rows_benchmark

BASE = ROOT / 'scenarios' / 'defaults_only.yaml'
ROWS: dict[str, tuple[str, list[str]]] = {
    'no spring': ('rover without a spring, R = 0.02 (the defaults)', ['plant.stiffness=0']),
    'paper plant': ("the paper's plant (spring 20 N/m), R = 0.02", ['plant.stiffness=20']),
    '110 kg': ('110 kg, 15 kg/s, no spring, limit 200 N',
               ['plant.stiffness=0', 'plant.mass=110', 'plant.damping=15',
                'plant.force_limit=200']),
    '120 kg, 8 kg/s': ('120 kg, 8 kg/s, no spring, limit 150 N',
                       ['plant.stiffness=0', 'plant.mass=120', 'plant.damping=8',
                        'plant.force_limit=150']),
    '120 kg': ('120 kg, default 45 kg/s, no spring, limit 150 N',
               ['plant.mass=120', 'plant.force_limit=150', 'plant.stiffness=0']),
    '120 kg, spring': ('120 kg, default 45 kg/s, spring 20 N/m, limit 150 N',
                       ['plant.mass=120', 'plant.force_limit=150', 'plant.stiffness=20']),
    'paper plant, R 0.005': ("the paper's plant at R = 0.005",
                             ['plant.stiffness=20', 'controller.R=0.005']),
}


def _fmt(value: float | None, digits: int) -> str:
    return '—' if value is None else f'{value:.{digits}f}'


def row_line(row: dict) -> str:
    """One row of the table, from the row's stats and its runs' control metrics."""
    s = row['stats']
    ci = s['success_rate_ci95']
    ci_text = f" ({100 * ci[0]:.0f}–{100 * ci[1]:.0f} %)" if ci else ''
    controls = [r['control'] for r in row['runs'] if isinstance(r.get('control'), dict)]
    ratios = [c['ratio_optimum_last10'] for c in controls
              if c.get('ratio_optimum_last10') is not None]
    optimum = (f'{min(ratios):.4f}–{max(ratios):.4f} ({sum(x <= 1.05 for x in ratios)} of '
               f'{len(ratios)})' if ratios else '—')
    c = s.get('control') or {}
    riccati = (f"{c['ratio_riccati_policy_median']:.3f} ({c['within_5pct']} / "
               f"{c['within_10pct']} of {c['runs']})" if c else '—')
    forces = [(k['max_abs_force_n'], k.get('force_limit_n')) for k in controls
              if k.get('max_abs_force_n') is not None]
    force = '—'
    if forces:
        worst, limit = max(forces)
        force = f'{worst:.0f} N' + (f' / {limit:.0f} N' if limit else '')
    path = s['path_over_optimum']
    return (f"| {row['label']} | {s['successes']}/{s['completed']}{ci_text} | "
            f"{s['collisions']} | {s.get('out_of_bounds', 0)} | "
            f"{_fmt(s['time_to_goal_s']['median'], 1)} | "
            f"{_fmt(path['median'], 3)} / {_fmt(path['p95'], 3)} | {optimum} | {riccati} | "
            f"{force} |")


def render(rows: list[dict]) -> str:
    """The table of the rows, the missions that failed and the commands."""
    lines = ['Every row from the controller\'s defaults (no controller key, no initial gain), '
             'undisturbed, on the random layouts of `rrtq bench scenarios/defaults_only.yaml` '
             '(8 obstacles per seed). Last ten: each run\'s median over its last ten legs of '
             'the leg cost against the Riccati optimum from the leg\'s start (range over the '
             'runs, runs within 5 %), and against the true Riccati policy flown through the '
             'same run (median over the runs, runs within 5 % / 10 %).', '',
             '| plant | goals (95 % CI) | collisions | out of bounds | time to goal s (median) '
             '| path / optimum (median / p95) | last ten / optimum: range (runs ≤ 1.05) '
             '| last ten / Riccati policy: median (within 5 % / 10 %) '
             '| largest command / limit |', '|---|---|---|---|---|---|---|---|---|']
    lines += [row_line(r) for r in rows]
    lines += failures_and_commands(rows)
    return '\n'.join(lines)


def main() -> int:
    return rows_benchmark('defaults_only', __doc__, ROWS, render, BASE)


if __name__ == '__main__':
    sys.exit(main())
