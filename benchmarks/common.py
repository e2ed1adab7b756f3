"""Shared bits of the benchmarks: machine description and result files."""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time
from typing import Any, Callable

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
               settings: list[str], run: bool = True) -> tuple[dict, str]:
    """Run ``rrtq bench BASE`` into ``out`` with ``options`` and ``--set`` ``settings``.

    Returns its sweep table (``out/sweep.json``) and the command as a user types it. Exit
    codes 0 and 1 (a run that failed on its engine) leave a table; any other stops the
    benchmark. ``run=False`` reads the table an earlier run left in ``out``.
    """
    cmd = [str(ROOT / 'scripts' / 'rrtq'), 'bench', str(base), *options, '--runs', str(out),
           '--out', str(out), '--overwrite']
    for s in settings:
        cmd += ['--set', s]
    if run:
        proc = subprocess.run(cmd, text=True, stdout=subprocess.PIPE, stderr=sys.stderr)
        if proc.returncode not in (0, 1):
            raise SystemExit(f'{name}: rrtq bench exited {proc.returncode}')
    elif not (out / 'sweep.json').exists():
        raise SystemExit(f'{name}: no earlier table in {out}')
    command = 'rrtq ' + ' '.join(cmd[1:]).replace(str(ROOT) + '/', '')
    return json.loads((out / 'sweep.json').read_text()), command


def bench_row(name: str, base: pathlib.Path, runs: pathlib.Path, options: list[str],
              settings: list[str], run: bool = True) -> dict:
    """One table row run as one ``rrtq bench`` of ``base`` in ``runs/<name>``.

    Returns the row's name, its command, the stats and runs of its one configuration and its
    wall time (s).
    """
    out = runs / name.replace(' ', '_').replace(',', '').replace('+', 'and')
    started = time.monotonic()
    table, command = rrtq_bench(name, base, out, options, settings, run=run)
    conf = table['configurations'][0]
    return {'name': name, 'command': command, 'machine': table.get('machine') or {},
            'stats': conf['stats'], 'runs': conf['runs'], 'wall_s': time.monotonic() - started}


def failures_and_commands(rows: list[dict]) -> list[str]:
    """The markdown lines under a table of rows: the missions that failed, each row's command."""
    failed = [(r['label'], f['seed'], f['outcome'], f['reason']) for r in rows
              for f in r['stats']['mission_failures']]
    lines = []
    if failed:
        lines += ['', 'Missions that failed:', '', '| row | seed | outcome | reason |',
                  '|---|---|---|---|']
        lines += [f'| {a} | {b} | {c} | {d} |' for a, b, c, d in failed]
    lines += ['', 'Commands (each row one `rrtq bench`):', '']
    lines += [f"- {r['label']}: `{r['command']}`" for r in rows]
    return lines


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


def rows_benchmark(name: str, description: str, rows: dict[str, tuple[str, list[str]]],
                   render: Callable[[list[dict]], str], base: pathlib.Path, *,
                   engine: str = 'local', settings: tuple[str, ...] = ()) -> int:
    """The command line of a benchmark whose rows are each one ``rrtq bench`` of ``base``.

    ``rows`` maps a row's name to its label and its ``--set`` settings (after ``settings``,
    common to every row); the rendered table goes to ``results/<name>.{md,json}``, or to
    stdout with ``--no-save``.
    """
    ap = argparse.ArgumentParser(description=description.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=20)
    ap.add_argument('--engine', choices=('local', 'ray'), default=engine)
    ap.add_argument('--workers', type=int, default=os.cpu_count() or 1)
    ap.add_argument('--rows', nargs='+', choices=sorted(rows), default=list(rows))
    ap.add_argument('--runs', type=pathlib.Path, default=ROOT / 'runs' / name)
    ap.add_argument('--no-save', action='store_true')
    ap.add_argument('--keep-others', action='store_true',
                    help='keep the saved rows not given with --rows (each says when and at '
                    'which commit it was measured)')
    ap.add_argument('--set', action='append', default=[], dest='extra', metavar='KEY=VALUE',
                    help='a setting for every row, after the row\'s own (e.g. '
                    'controller.integral_action=true; the rows\' commands say so)')
    ap.add_argument('--tabulate', action='store_true',
                    help='read the rows from the tables an earlier run left in --runs '
                    'instead of running them')
    args = ap.parse_args()
    measured = {k: machine(ROOT)[k] for k in ('date', 'commit')}
    done = []
    for row_name in args.rows:
        label, row_settings = rows[row_name]
        print(f'{name}: {row_name} ({label})', file=sys.stderr, flush=True)
        row = bench_row(row_name, base, args.runs, ['--seeds', str(args.seeds), '--engine',
                                                    args.engine, '--workers', str(args.workers)],
                        [*settings, *row_settings, *args.extra], run=not args.tabulate)
        row['label'] = label
        row['measured'] = ({k: row['machine'].get(k) for k in ('date', 'commit')}
                           if args.tabulate else measured)
        done.append(row)
    if args.keep_others:
        done = kept_rows(name, list(rows), done)
    table = render(done) + measured_lines(done)
    if args.no_save:
        print(table)
    else:
        save(name, {'seeds': args.seeds, 'rows': done}, table)
    return 0


def kept_rows(name: str, order: list[str], new: list[dict]) -> list[dict]:
    """The rows of the saved ``results/<name>.json`` with ``new`` in place of their namesakes.

    In the benchmark's row order; a kept row without a measurement of its own was measured
    when its file says.
    """
    path = RESULTS / f'{name}.json'
    if not path.exists():
        return new
    saved = json.loads(path.read_text())
    when = {k: saved.get('machine', {}).get(k) for k in ('date', 'commit')}
    rows = {r['name']: {**r, 'measured': r.get('measured') or when} for r in saved['rows']}
    rows.update({r['name']: r for r in new})
    return [rows[n] for n in order if n in rows]


def measured_lines(rows: list[dict]) -> str:
    """Under a table whose rows were measured at different times: when each was."""
    stamps = {(r.get('measured') or {}).get('commit') for r in rows}
    if len(stamps) <= 1:
        return ''
    lines = ['', '', 'Measured (rows re-run since the rest):', '']
    lines += [f"- {r['label']}: {r['measured'].get('date')}, commit {r['measured'].get('commit')}"
              for r in rows]
    return '\n'.join(lines)
