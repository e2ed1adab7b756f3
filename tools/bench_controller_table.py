"""Per-seed controller table of an ``rrtq bench`` run directory, from its recordings alone.

For each seed's recording: the outcome (its summary.json), the median over the last ten
legs of each leg's cost against the Riccati optimum from its start
(:mod:`rrtq_bringup.leg_table`), the largest commanded force per axis on ``/cmd_force``,
and the guard's reverts and holds (``/controller/state.policy_event``). Its rows made the
per-seed tables of the defaults-only rounds
(``docs/notes/2026-12-02-safe-learning-from-defaults.md``).

    python tools/bench_controller_table.py RUNS_DIR [RUNS_DIR ...] [--label LABEL ...]

RUNS_DIR is the ``--runs`` directory of one bench configuration (``cfg-00`` inside it,
or the directory holding ``seed-NNN``); each gets its label (default: the directory's
name) in the first column.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

from rrtq_bringup.bench.control import control_metrics


def seed_row(seed_dir: pathlib.Path) -> dict:
    """The row of one seed's run directory (run.mcap and summary.json), read once."""
    outcome = json.loads((seed_dir / 'summary.json').read_text())['outcome']
    metrics = control_metrics(seed_dir) or {}
    return {'seed': seed_dir.name, 'outcome': outcome,
            'ratio': metrics.get('ratio_optimum_last10'),
            'ratio_riccati': metrics.get('ratio_riccati_policy_last10'),
            'u_max': metrics.get('max_abs_force_n', 0.0),
            'reverted': metrics.get('reverts', 0), 'hold': metrics.get('holds', 0)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('runs', nargs='+', type=pathlib.Path)
    ap.add_argument('--label', nargs='+', action='extend', default=[],
                    help='labels of the runs in order (repeat the flag or list them)')
    args = ap.parse_args(argv)
    print('| configuration | seed | outcome | last-ten leg cost / optimum | last-ten leg cost / '
          'Riccati policy | max abs(u) N | reverts | holds |')
    print('|---|---|---|---|---|---|---|---|')
    for i, runs in enumerate(args.runs):
        label = args.label[i] if i < len(args.label) else runs.name
        seeds = sorted(runs.glob('seed-*')) or sorted(runs.glob('*/seed-*'))
        if not seeds:
            print(f'{runs}: no seed-NNN directories', file=sys.stderr)
            return 2
        for seed_dir in seeds:
            r = seed_row(seed_dir)
            ratio = '—' if r['ratio'] is None else f"{r['ratio']:.4f}"
            riccati = '—' if r['ratio_riccati'] is None else f"{r['ratio_riccati']:.4f}"
            print(f"| {label} | {r['seed']} | {r['outcome']} | {ratio} | {riccati} | {r['u_max']:.1f} "
                  f"| {r['reverted']} | {r['hold']} |", flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
