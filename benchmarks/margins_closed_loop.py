#!/usr/bin/env python3
"""Safety margins in the closed loop: running_max against learned_bound on five scenarios.

Each scenario (``scenarios/narrow_gap.yaml`` and ``benchmarks/margins_scenarios/``'s
``defaults_gap``, ``two_bumps``, ``bump_mid``, ``heavy_gap``) is one ``rrtq bench`` with
its own obstacles kept and no random ones, ``--set safety.margin=running_max,learned_bound``,
8 seeds. Per scenario and mode: goals, collisions, time to goal, path over the optimum,
replans, and the legs whose realised deviation exceeded the margin in force, from the
recordings alone (:mod:`rrtq_bringup.margin_coverage`) with 95 % Clopper-Pearson intervals:
over all legs, in each mission's first three legs (learned_bound's fallback, before it has a
contracting model), after them, and the missions compatible with δ on their own.

Usage: ``.venv/bin/python benchmarks/margins_closed_loop.py [--seeds 8] [--scenarios NAME ...]
[--runs DIR]``; writes ``benchmarks/results/margins_closed_loop.{json,md}``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

from common import ROOT, rrtq_bench, save
from rrtq_bringup.margin_coverage import coverage
from rrtq_planner.margins.coverage import binomial_interval

SCENARIOS = {
    'defaults_gap': ROOT / 'benchmarks' / 'margins_scenarios' / 'defaults_gap.yaml',
    'narrow_gap': ROOT / 'scenarios' / 'narrow_gap.yaml',
    'two_bumps': ROOT / 'benchmarks' / 'margins_scenarios' / 'two_bumps.yaml',
    'bump_mid': ROOT / 'benchmarks' / 'margins_scenarios' / 'bump_mid.yaml',
    'heavy_gap': ROOT / 'benchmarks' / 'margins_scenarios' / 'heavy_gap.yaml',
}
MODES = 'safety.margin=running_max,learned_bound'
EARLY_LEGS = 3


def _fmt(value: float | None) -> str:
    return '—' if value is None else f'{value:.1f}'


def mode_row(conf: dict) -> dict:
    """One mode of one scenario: the sweep's stats and the recordings' coverage."""
    s = conf['stats']
    legs = misses = early_legs = early_misses = not_compatible = 0
    for run in conf['runs']:
        recording = pathlib.Path(run['dir']) / 'run.mcap'
        if not recording.is_file():
            continue
        cov = coverage([recording])
        legs, misses = legs + len(cov.legs), misses + cov.misses
        early = cov.legs[:EARLY_LEGS]
        early_legs += len(early)
        early_misses += sum(not leg.covered for leg in early)
        not_compatible += not cov.passed
    path = s['path_over_optimum']
    return {'mode': conf['overrides']['safety.margin'], 'runs': s['completed'],
            'goals': s['successes'], 'collisions': s['collisions'],
            'time': _fmt(s['time_to_goal_s']['median']),
            'path': ('—' if path['median'] is None
                     else f"{path['median']:.3f} / {path['p95']:.3f}"),
            'replans': _fmt(s['replans']['median']),
            'legs': legs, 'misses': misses, 'ci': list(binomial_interval(misses, legs)),
            'early_legs': early_legs, 'early_misses': early_misses,
            'later_ci': list(binomial_interval(misses - early_misses, legs - early_legs)),
            'missions_not_compatible': not_compatible}


def render(scenarios: dict[str, list[dict]]) -> str:
    """The table, a row per scenario and mode."""
    lines = ['Each scenario\'s own obstacles, no random ones, default `safety:` keys but the '
             'mode. Legs above their margin come from the recordings '
             '(`python -m rrtq_bringup.margin_coverage`), with 95 % Clopper-Pearson intervals; '
             '"legs 0–2" are each mission\'s first three legs (learned_bound\'s fallback: no '
             'contracting model yet, so the running max at the leg\'s start); "missions '
             'compatible": each recording alone, the lower end of its interval at most '
             'δ = 0.05.', '',
             '| scenario | mode | goals | collisions | time to goal s (median) | path / optimum '
             '(median / p95) | replans (median) | legs above their margin [95 %] | of them in '
             'legs 0–2 | after leg 2 [95 %] | missions compatible |',
             '|---|---|---|---|---|---|---|---|---|---|---|']
    for name, rows in scenarios.items():
        for r in rows:
            later_legs = r['legs'] - r['early_legs']
            later = r['misses'] - r['early_misses']
            lines.append(
                f"| {name} | {r['mode']} | {r['goals']}/{r['runs']} | {r['collisions']} | "
                f"{r['time']} | {r['path']} | {r['replans']} | "
                f"{r['misses']}/{r['legs']}, {r['misses'] / max(r['legs'], 1):.3f} "
                f"[{r['ci'][0]:.3f}, {r['ci'][1]:.3f}] | {r['early_misses']}/{r['early_legs']} | "
                f"{later}/{later_legs}, {later / max(later_legs, 1):.3f} "
                f"[{r['later_ci'][0]:.3f}, {r['later_ci'][1]:.3f}] | "
                f"{r['runs'] - r['missions_not_compatible']}/{r['runs']} |")
    return '\n'.join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=8)
    ap.add_argument('--workers', type=int, default=os.cpu_count() or 1)
    ap.add_argument('--scenarios', nargs='+', choices=sorted(SCENARIOS), default=list(SCENARIOS))
    ap.add_argument('--runs', type=pathlib.Path, default=ROOT / 'runs' / 'margins_closed_loop')
    ap.add_argument('--no-save', action='store_true')
    args = ap.parse_args()
    scenarios, commands = {}, []
    for name in args.scenarios:
        print(f'margins_closed_loop: {name}', file=sys.stderr, flush=True)
        table, command = rrtq_bench(name, SCENARIOS[name], args.runs / name,
                                    ['--obstacles', '0', '--keep-obstacles', '--seeds',
                                     str(args.seeds), '--workers', str(args.workers)], [MODES])
        scenarios[name] = [mode_row(conf) for conf in table['configurations']]
        commands.append(command)
    text = render(scenarios) + '\n\nCommands:\n\n' + '\n'.join(f'- `{c}`' for c in commands)
    if args.no_save:
        print(text)
    else:
        save('margins_closed_loop', {'seeds': args.seeds, 'scenarios': scenarios,
                                     'commands': commands}, text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
