#!/usr/bin/env python3
"""The rows of ``robot_side`` with the LQ-optimal push feed-forward on (opt-in).

The same ``rrtq bench`` rows as ``benchmarks/robot_side.py`` (the controller's defaults,
blind to the disturbance) with ``--set controller.push_feedforward=true`` and its default
law, ``push_feedforward_law: optimal`` (``rrtq_controller.push_feedforward``: the
certainty-equivalent LQ feed-forward of the push the identified model predicts). Compare
each row with its namesake in ``results/robot_side.md`` (no feed-forward) and
``results/robot_side_push_feedforward.md`` (the cancelling law).

Usage: ``.venv/bin/python benchmarks/push_feedforward.py [--seeds 20] [--rows NAME ...]
[--runs DIR] [--keep-others]``; writes ``benchmarks/results/push_feedforward.{json,md}``.
"""

from __future__ import annotations

import sys

from common import rows_benchmark
from robot_side import BASE, DURATION, ROWS
from robot_side import render as robot_side_table

FEEDFORWARD = 'controller.push_feedforward=true'


def render(rows: list[dict]) -> str:
    """The robot_side table of the rows, the feed-forward said first."""
    return ('**Opt-in: the LQ-optimal push feed-forward** (`--set '
            'controller.push_feedforward=true`, law `optimal`, docs/observer.md §7); the same '
            'rows without it: [robot_side.md](robot_side.md), with the cancelling law: '
            '[robot_side_push_feedforward.md](robot_side_push_feedforward.md).\n\n'
            + robot_side_table(rows))


def main() -> int:
    return rows_benchmark('push_feedforward', __doc__, ROWS, render, BASE, engine='local',
                          settings=(DURATION, FEEDFORWARD))


if __name__ == '__main__':
    sys.exit(main())
