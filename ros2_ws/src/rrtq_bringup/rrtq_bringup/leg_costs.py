"""``python -m rrtq_bringup.leg_costs RUN.mcap [--json]``: per-leg cost against the optimum.

The legs of a recording, each with its cost and the Riccati optimum of the same
finite-horizon problem (:mod:`rrtq_bringup.leg_table` explains the method), from the
recording alone: its messages and the scenario embedded in it.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

from rrtq_bringup.leg_table import (QUADRATURES, LegTable, Quadrature, format_table, leg_table,
                                    summary)
from rrtq_bringup.run_data import embedded_scenario, read_run, recorded_scenario


def evaluate(path: str | pathlib.Path, quadrature: str = Quadrature.ZOH) -> LegTable:
    """Read a recording and its embedded scenario, and evaluate every leg."""
    if not embedded_scenario(path):
        raise ValueError(f'{path}: no embedded scenario (metadata record rrtq_scenario)')
    # the plant and the weights are all a leg's cost needs; obstacle files named by the
    # scenario need not be where the recording is now
    return leg_table(read_run(path), recorded_scenario(path), quadrature)


def main(argv: list[str] | None = None) -> int:
    """``python -m rrtq_bringup.leg_costs RUN.mcap [--json]``: print the leg table."""
    ap = argparse.ArgumentParser(description='Per-leg cost / Riccati optimum of a recording')
    ap.add_argument('mcap')
    ap.add_argument('--quadrature', choices=QUADRATURES, default=Quadrature.ZOH.value)
    ap.add_argument('--json', action='store_true', help='print the summary as JSON')
    args = ap.parse_args(argv)
    table = evaluate(args.mcap, args.quadrature)
    if args.json:
        print(json.dumps(summary(table), indent=1))
    else:
        s = summary(table)
        print(format_table(table))
        print(f"\nlegs {s['legs']}; median ratio over the last 10: {s['median_ratio_last10']}"
              f" (complete legs: {s['median_ratio_last10_complete']}); against the Riccati"
              f" policy through the recorded disturbance: {s['median_ratio_riccati_policy_last10']};"
              f" {s['anchor']}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
