#!/usr/bin/env python3
"""Safety margins in the closed loop: the calibrated learned bound, uncalibrated, running_max.

Five scenarios (``scenarios/narrow_gap.yaml`` and ``benchmarks/margins_scenarios/``'s
``defaults_gap``, ``two_bumps``, ``bump_mid``, ``heavy_gap``), each with its own obstacles
kept and no random ones, and ``layouts``: narrow_gap's field and route among the bench's 8
random obstacles per seed. Per scenario (docs/margins.md §10):

1. a calibration: ``rrtq bench --set safety.margin=learned_bound`` on seeds 100 on, which
   pools its runs' leg scores into ``calibration-cfg-00.json``; with ``--rounds 2`` a
   second round, the same seeds flown by the calibrated policy from that file
   (``calibration-2``), whose own scores are the calibration of the policy under test;
2. ``learned_bound`` from that calibration (``safety.calibration``, other seeds than the
   calibration's: 0 on), conformal (the default) and ``safety.conformal=false``;
3. ``running_max`` on the same seeds.

Per mode: goals, collisions, time to goal, path over the optimum, replans, the mean margin
in force per leg, and the legs whose realised deviation exceeded the margin in force, from
the recordings alone (:mod:`rrtq_bringup.margin_coverage`) with 95 % Clopper-Pearson
intervals: over all legs, in each mission's first three legs, after them, and the missions
compatible with δ on their own.

Usage: ``.venv/bin/python benchmarks/margins_closed_loop.py [--seeds 20] [--compare-seeds 10]
[--calibration-seeds 20] [--scenarios NAME ...] [--runs DIR]``; writes
``benchmarks/results/margins_closed_loop.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
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
    'layouts': ROOT / 'scenarios' / 'narrow_gap.yaml',
}
OBSTACLES = {'layouts': ['--obstacles', '8']}
"""Per scenario, how its obstacles are made (default: its own, no random ones)."""
CALIBRATION_FIRST_SEED = 100
EARLY_LEGS = 3


def _fmt(value: float | None) -> str:
    return '—' if value is None else f'{value:.1f}'


def leg_tubes(recording: pathlib.Path) -> dict[int, tuple[float, bool | None]]:
    """Per controller leg index, the tube at its start and whether it rested on a refuted level.

    The tube is /safety/status's (0: none); None for the level: a recording older than the
    field.
    """
    from rrtq_bringup.run_data import messages, safety_legs

    return {leg.index: (leg.tube, leg.refuted)
            for leg in safety_legs(messages(recording, '/safety/status'), by='leg_index')}


def mode_row(conf: dict, mode: str) -> dict:
    """One mode of one scenario: the sweep's stats and the recordings' coverage."""
    s = conf['stats']
    legs = misses = early_legs = early_misses = not_compatible = 0
    margins: list[float] = []
    first = [0, 0]           # legs that started without a model (learned_bound), misses
    refuted: list[int] | None = [0, 0]   # legs whose tube rested on a refuted level, misses
    for run in conf['runs']:
        recording = pathlib.Path(run['dir']) / 'run.mcap'
        if not recording.is_file():
            continue
        cov = coverage([recording])
        legs, misses = legs + len(cov.legs), misses + cov.misses
        margins += [leg.margin for leg in cov.legs]
        tubes = leg_tubes(recording)
        without = [leg for leg in cov.legs if tubes.get(leg.index, (0.0, None))[0] <= 0.0]
        first = [first[0] + len(without), first[1] + sum(not leg.covered for leg in without)]
        if any(up is None for _, up in tubes.values()):
            refuted = None
        elif refuted is not None:
            up = [leg for leg in cov.legs if tubes.get(leg.index, (0.0, False))[1]]
            refuted = [refuted[0] + len(up), refuted[1] + sum(not leg.covered for leg in up)]
        early = cov.legs[:EARLY_LEGS]
        early_legs += len(early)
        early_misses += sum(not leg.covered for leg in early)
        not_compatible += not cov.passed
    path = s['path_over_optimum']
    return {'mode': mode, 'runs': s['completed'],
            'mean_margin': sum(margins) / len(margins) if margins else None,
            'first_legs': first[0], 'first_misses': first[1],
            'refuted_legs': None if refuted is None else refuted[0],
            'refuted_misses': None if refuted is None else refuted[1],
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
    lines = ['Each scenario\'s own obstacles, no random ones (`layouts`: narrow_gap\'s field '
             'and route among 8 random obstacles per seed), default `safety:` keys but the '
             'mode. `learned_bound` starts from a calibration pooled by `rrtq bench` from '
             'other seeds of the same scenario (seeds 100 on), conformal (the default) and '
             'not (`conformal=false`, which ignores it). Legs above their margin come from '
             'the recordings (`python -m rrtq_bringup.margin_coverage`: the least margin '
             'published while the leg ran), with 95 % Clopper-Pearson intervals; "legs 0–2" '
             'are each mission\'s first three legs; "without a model": learned_bound\'s legs '
             'that started with no contracting model (`leg_tube` 0; the calibrated mode\'s '
             'first-leg category, docs/margins.md §10); "on a refuted level": legs whose tube '
             'rested on a bound residuals had raised above the prior bound (`leg_refuted`, '
             'the third category; — for recordings made before it); "mean margin": over legs, '
             'the margin in force; "missions compatible": each recording alone, the lower end '
             'of its interval at most δ = 0.05.', '',
             '| scenario | mode | goals | collisions | time to goal s (median) | path / optimum '
             '(median / p95) | replans (median) | mean margin m | legs above their margin '
             '[95 %] | of them in legs 0–2 | after leg 2 [95 %] | legs without a model above '
             'their margin | legs on a refuted level above their margin | missions compatible |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for name, rows in scenarios.items():
        for r in rows:
            later_legs = r['legs'] - r['early_legs']
            later = r['misses'] - r['early_misses']
            lines.append(
                f"| {name} | {r['mode']} | {r['goals']}/{r['runs']} | {r['collisions']} | "
                f"{r['time']} | {r['path']} | {r['replans']} | "
                f"{'—' if r.get('mean_margin') is None else format(r['mean_margin'], '.2f')} | "
                f"{r['misses']}/{r['legs']}, {r['misses'] / max(r['legs'], 1):.3f} "
                f"[{r['ci'][0]:.3f}, {r['ci'][1]:.3f}] | {r['early_misses']}/{r['early_legs']} | "
                f"{later}/{later_legs}, {later / max(later_legs, 1):.3f} "
                f"[{r['later_ci'][0]:.3f}, {r['later_ci'][1]:.3f}] | "
                # (— where no leg recorded a tube: running_max, or a recording without it)
                + (f"{r['first_misses']}/{r['first_legs']} | "
                   if r.get('first_legs', r['legs']) < r['legs'] else '— | ') +
                (f"{r['refuted_misses']}/{r['refuted_legs']} | "
                 if r.get('refuted_legs') is not None and r['mode'] != 'running_max'
                 else '— | ') +
                f"{r['runs'] - r['missions_not_compatible']}/{r['runs']} |")
    return '\n'.join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=20,
                    help='seeds of the calibrated learned_bound (0 on)')
    ap.add_argument('--compare-seeds', type=int, default=10,
                    help='seeds of the uncalibrated learned_bound and running_max (0 on)')
    ap.add_argument('--calibration-seeds', type=int, default=20,
                    help=f'seeds of the calibration ({CALIBRATION_FIRST_SEED} on)')
    ap.add_argument('--rounds', type=int, choices=(1, 2), default=1,
                    help='calibration rounds: 1, the calibration seeds flown without one (what '
                    'a user\'s first bench gives); 2, then flown again from it')
    ap.add_argument('--workers', type=int, default=os.cpu_count() or 1)
    ap.add_argument('--scenarios', nargs='+', choices=sorted(SCENARIOS), default=list(SCENARIOS))
    ap.add_argument('--runs', type=pathlib.Path, default=ROOT / 'runs' / 'margins_closed_loop')
    ap.add_argument('--no-save', action='store_true')
    ap.add_argument('--keep', nargs='+', default=[],
                    choices=('calibration', 'uncalibrated', 'running_max'),
                    help='keep these benches of an earlier call in --runs instead of running '
                    'them again (none of them runs the calibrated code)')
    ap.add_argument('--tabulate', action='store_true',
                    help='read the runs an earlier call left in --runs instead of running')
    args = ap.parse_args()
    scenarios, commands = {}, []
    for name in args.scenarios:
        print(f'margins_closed_loop: {name}', file=sys.stderr, flush=True)
        base = SCENARIOS[name]
        options = OBSTACLES.get(name, ['--obstacles', '0', '--keep-obstacles'])
        runs = args.runs / name

        def bench(what: str, seeds: int, first: int, settings: list[str],
                  name: str = name, base: pathlib.Path = base, options: list[str] = options,
                  runs: pathlib.Path = runs, keep: bool = False) -> dict:
            table, command = rrtq_bench(f'{name} {what}', base, runs / what,
                                        [*options, '--seeds', str(seeds), '--first-seed',
                                         str(first), '--workers', str(args.workers)], settings,
                                        run=not (args.tabulate or keep))
            commands.append(command)
            return table

        calibration = (runs / 'calibration' / 'calibration-cfg-00.json').resolve()
        bench('calibration', args.calibration_seeds, CALIBRATION_FIRST_SEED,
              ['safety.margin=learned_bound'],
              keep='calibration' in args.keep and calibration.exists())
        if args.rounds == 2:
            # The calibration seeds flown by the calibrated policy itself, from the first
            # round's file; their own scores calibrate the policy under test (the first
            # round's missions were flown uncalibrated: other routes, other legs).
            second = (runs / 'calibration-2' / 'calibration-cfg-00.json').resolve()
            bench('calibration-2', args.calibration_seeds, CALIBRATION_FIRST_SEED,
                  ['safety.margin=learned_bound', f'safety.calibration={calibration}'],
                  keep='calibration' in args.keep and second.exists())
            calibration = second

        pooled = json.loads(calibration.read_text())
        print(f'margins_closed_loop: {name}: calibration of {len(pooled["normalized"])} '
              f'normalized, {len(pooled.get("refuted", []))} refuted and '
              f'{len(pooled["prior"])} prior scores', file=sys.stderr)
        calibrated = bench('learned_bound', args.seeds, 0, [
            'safety.margin=learned_bound', f'safety.calibration={calibration}'])
        rows = [mode_row(calibrated['configurations'][0], 'learned_bound, calibrated')]
        uncalibrated = bench('uncalibrated', args.compare_seeds, 0, [
            'safety.margin=learned_bound', 'safety.conformal=false'],
            keep='uncalibrated' in args.keep and (runs / 'uncalibrated').exists())
        rows.append(mode_row(uncalibrated['configurations'][0], 'learned_bound, conformal=false'))
        running_max = bench('running_max', args.compare_seeds, 0, ['safety.margin=running_max'],
                            keep='running_max' in args.keep and (runs / 'running_max').exists())
        rows.append(mode_row(running_max['configurations'][0], 'running_max'))
        scenarios[name] = rows
    text = render(scenarios) + '\n\nCommands:\n\n' + '\n'.join(f'- `{c}`' for c in commands)
    if args.no_save:
        print(text)
    else:
        save('margins_closed_loop', {'seeds': args.seeds, 'scenarios': scenarios,
                                     'commands': commands}, text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
