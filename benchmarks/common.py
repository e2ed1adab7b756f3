"""Shared bits of the benchmarks: machine description and result files."""

from __future__ import annotations

import json
import pathlib
import time
from typing import Any

from rrtq_bringup.bench_table import machine

RESULTS = pathlib.Path(__file__).resolve().parent / 'results'
ROOT = RESULTS.parents[1]


def save(name: str, results: dict, table: str) -> None:
    """Write ``results/<name>.json`` and ``results/<name>.md`` (the table, with the machine)."""
    RESULTS.mkdir(exist_ok=True)
    info = machine(ROOT)
    (RESULTS / f'{name}.json').write_text(json.dumps({'machine': info, **results}, indent=2)
                                          + '\n')
    header = (f"_{info['date']}, {info['cpu']} ({info['cores']} cores), Python "
              f"{info['python']}, commit {info['commit']}_\n\n")
    (RESULTS / f'{name}.md').write_text(header + table + '\n')
    print(header + table)


def time_steps(ctrl: Any) -> list[float]:
    """Wrap ``ctrl.step`` so that each call's wall time (s) lands in the returned list."""
    times: list[float] = []
    step = ctrl.step

    def timed(t, x, d_applied=None):
        t0 = time.perf_counter()
        u = step(t, x, d_applied)
        times.append(time.perf_counter() - t0)
        return u

    ctrl.step = timed
    return times
