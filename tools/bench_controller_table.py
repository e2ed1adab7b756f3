"""Per-seed controller table of an ``rrtq bench`` run directory, from its recordings alone.

For each seed's recording: the outcome (its summary.json), the median over the last ten
legs of each leg's cost against the Riccati optimum from its start
(:mod:`rrtq_bringup.leg_table`), the largest commanded force per axis on ``/cmd_force``,
and the guard's reverts and holds (``/controller/state.policy_event``). The rows are the
markdown table of ``benchmarks/results/defaults_only_bench.md``.

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

import numpy as np

from rrtq_bringup.leg_table import leg_table, summary
from rrtq_bringup.run_data import read_run, recorded_scenario


def seed_row(seed_dir: pathlib.Path) -> dict:
    """The row of one seed's run directory (run.mcap and summary.json), read once."""
    mcap = seed_dir / 'run.mcap'
    outcome = json.loads((seed_dir / 'summary.json').read_text())['outcome']
    data = read_run(mcap)
    events = [e for _, joined, _ in data.policy_events for e in joined.split(';')]
    ratio = summary(leg_table(data, recorded_scenario(mcap)))['median_ratio_last10']
    u_max = float(np.abs(data.cmd_u).max(initial=0.0))
    return {'seed': seed_dir.name, 'outcome': outcome, 'ratio': ratio, 'u_max': u_max,
            'reverted': events.count('reverted'), 'hold': events.count('hold')}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('runs', nargs='+', type=pathlib.Path)
    ap.add_argument('--label', nargs='+', action='extend', default=[],
                    help='labels of the runs in order (repeat the flag or list them)')
    args = ap.parse_args(argv)
    print('| configuration | seed | outcome | last-ten leg cost / optimum | max abs(u) N | reverts '
          '| holds |')
    print('|---|---|---|---|---|---|---|')
    for i, runs in enumerate(args.runs):
        label = args.label[i] if i < len(args.label) else runs.name
        seeds = sorted(runs.glob('seed-*')) or sorted(runs.glob('*/seed-*'))
        if not seeds:
            print(f'{runs}: no seed-NNN directories', file=sys.stderr)
            return 2
        for seed_dir in seeds:
            r = seed_row(seed_dir)
            ratio = '—' if r['ratio'] is None else f"{r['ratio']:.4f}"
            print(f"| {label} | {r['seed']} | {r['outcome']} | {ratio} | {r['u_max']:.1f} "
                  f"| {r['reverted']} | {r['hold']} |", flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
