"""Shared bits of the benchmarks: machine description and result files."""

from __future__ import annotations

import json
import pathlib
import subprocess
import sys
import time
from typing import Any

from rrtq_bringup.bench.table import machine

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


def rrtq_bench(name: str, base: pathlib.Path, out: pathlib.Path, options: list[str],
               settings: list[str]) -> tuple[dict, str]:
    """Run ``rrtq bench BASE`` into ``out`` with ``options`` and ``--set`` ``settings``.

    Returns its sweep table (``out/sweep.json``) and the command as a user types it. Exit
    codes 0 and 1 (a run that failed on its engine) leave a table; any other stops the
    benchmark.
    """
    cmd = [str(ROOT / 'scripts' / 'rrtq'), 'bench', str(base), *options, '--runs', str(out),
           '--out', str(out), '--overwrite']
    for s in settings:
        cmd += ['--set', s]
    proc = subprocess.run(cmd, text=True, stdout=subprocess.PIPE, stderr=sys.stderr)
    if proc.returncode not in (0, 1):
        raise SystemExit(f'{name}: rrtq bench exited {proc.returncode}')
    command = 'rrtq ' + ' '.join(cmd[1:]).replace(str(ROOT) + '/', '')
    return json.loads((out / 'sweep.json').read_text()), command


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
