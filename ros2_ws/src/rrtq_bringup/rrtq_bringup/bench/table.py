"""The Monte Carlo table: per-run rows in, rates and percentiles out (Markdown and JSON).

A row is one seed: what the bench knows (seed, status, optimum) and the run's
``summary.json``. Rates are over the runs that completed (their summary was written
and they were not interrupted); time to goal and path length against the optimum are
over the successful runs; latencies take the per-run medians and 95th percentiles.
"""

from __future__ import annotations

import datetime
import math
import os
import pathlib
import platform
import subprocess
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from rrtq_bringup.bench.control import aggregate_control

__all__ = ['aggregate', 'machine', 'markdown', 'wilson']

COMPLETED = 'completed'


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float] | None:
    """Wilson score interval of a rate (95 % by default); None without trials."""
    if n == 0:
        return None
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def _stats(values: Sequence[float | None], *qs: int) -> dict[str, float | None]:
    finite = [float(v) for v in values if v is not None and math.isfinite(v)]
    names = {50: 'median', 95: 'p95'}
    return {names[q]: (float(np.percentile(finite, q)) if finite else None) for q in qs}


def _nested(rows: Sequence[dict], key: str, inner: str) -> list[float | None]:
    return [(row['summary'].get(key) or {}).get(inner) for row in rows]


def aggregate(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Rates and statistics over the rows (see the module docstring).

    Parameters
    ----------
    rows : sequence of dict
        Each with ``seed``, ``status`` ('completed', or why the run did not complete),
        ``optimum_m`` and, when completed, ``summary`` (the run's summary.json).
    """
    done = [r for r in rows if r['status'] == COMPLETED]
    wins = [r for r in done if r['summary']['success']]
    crashes = [r for r in done if r['summary']['collided']]
    ratios = [r['summary']['path_length_m'] / r['optimum_m'] for r in wins]
    return {
        'runs': len(rows),
        'completed': len(done),
        'successes': len(wins),
        'collisions': len(crashes),
        'success_rate': len(wins) / len(done) if done else None,
        'success_rate_ci95': wilson(len(wins), len(done)),
        'collision_rate': len(crashes) / len(done) if done else None,
        'out_of_bounds': sum(1 for r in done if r['summary']['outcome'] == 'out_of_bounds'),
        'outcomes': dict(Counter(r['summary']['outcome'] for r in done)),
        'time_to_goal_s': _stats([r['summary']['time_to_goal_s'] for r in wins], 50, 95),
        'path_over_optimum': _stats(ratios, 50, 95),
        'replans': _stats([r['summary']['replans'] for r in done], 50),
        'replan_ms': {'median': _stats(_nested(done, 'replan_ms', 'median'), 50)['median'],
                      'p95': _stats(_nested(done, 'replan_ms', 'p95'), 95)['p95']},
        'controller_step_ms': {
            'median': _stats(_nested(done, 'controller_step_ms', 'median'), 50)['median'],
            'p95': _stats(_nested(done, 'controller_step_ms', 'p95'), 95)['p95']},
        'sim_speedup': _stats([r['summary'].get('sim_speedup') for r in done], 50),
        'run_wall_s': _stats([r['summary'].get('wall_time_s') for r in done], 50),
        'mission_failures': [{'seed': r['seed'], 'outcome': r['summary']['outcome'],
                              'reason': r['summary']['reason']}
                             for r in done if not r['summary']['success']],
        'incomplete': [{'seed': r['seed'], 'reason': r['status']}
                       for r in rows if r['status'] != COMPLETED],
        'control': aggregate_control(done),
    }


def machine(repo: pathlib.Path) -> dict[str, Any]:
    """CPU model, cores, Python, kernel, date (UTC) and the commit of ``repo`` (``+dirty`` if so).

    Every benchmark result names the machine with this (``benchmarks/common.py`` too).
    """
    cpu = platform.processor() or 'unknown CPU'
    try:
        with open('/proc/cpuinfo', encoding='utf-8') as fh:
            names = [ln.split(':', 1)[1].strip() for ln in fh if ln.startswith('model name')]
        cpu = names[0] if names else cpu
    except OSError:
        pass

    def git(*args: str) -> str:
        done = subprocess.run(['git', *args], cwd=repo, capture_output=True, text=True)
        return done.stdout.strip() if done.returncode == 0 else ''

    commit = git('rev-parse', '--short', 'HEAD') or 'unknown'
    if git('status', '--porcelain', '--untracked-files=no'):
        commit += '+dirty'
    now = datetime.datetime.now(datetime.timezone.utc)
    return {'cpu': cpu, 'cores': os.cpu_count(), 'python': platform.python_version(),
            'kernel': platform.release(), 'date': now.strftime('%Y-%m-%d %H:%M UTC'),
            'commit': commit}


def num(value: float | None, digits: int = 2) -> str:
    return '—' if value is None else f'{value:.{digits}f}'


def pct(value: float | None) -> str:
    return '—' if value is None else f'{100.0 * value:.0f} %'


def control_rows(c: dict[str, Any] | None) -> list[tuple[str, str]]:
    """The controller's lines of the Monte Carlo table (:mod:`rrtq_bringup.bench.control`)."""
    if c is None:
        return []
    return [('last-ten leg cost / Riccati policy through the same disturbance, noise and delay '
             '(median / p90; runs within 5 %, 10 %)',
             f"{num(c['ratio_riccati_policy_median'], 3)} / {num(c['ratio_riccati_policy_p90'], 3)}"
             f"; {c['within_5pct']} and {c['within_10pct']} of {c['runs']}"),
            ('largest command / actuator limit (runs beyond it)',
             f"{num(c['max_force_over_limit'], 3)} ({c['beyond_limit']})")]


def control_cell(c: dict[str, Any] | None) -> str:
    """One sweep-table cell: median ratio to the Riccati policy, and runs within 5 % / 10 %."""
    if c is None:
        return '—'
    return (f"{num(c['ratio_riccati_policy_median'], 3)} ({c['within_5pct']} / "
            f"{c['within_10pct']} of {c['runs']})")


def cell(text: str) -> str:
    return text.replace('|', '\\|').replace('\n', ' ')


def markdown(table: dict[str, Any]) -> str:
    """The table as Markdown: a header line (machine, command), the metrics, the failures."""
    info, s = table['machine'], table['stats']
    engine = table.get('engine', f"local, {table['workers']} workers")
    ci = s['success_rate_ci95']
    ci_text = f' (95 % CI {pct(ci[0])}–{pct(ci[1])})' if ci else ''
    rows = [
        ('runs completed', f"{s['completed']} of {s['runs']} (seeds {table['seeds']})"),
        ('success rate', f"{pct(s['success_rate'])}{ci_text}"),
        ('collision rate', pct(s['collision_rate'])),
        ('out of bounds', str(s.get('out_of_bounds', 0))),
        ('outcomes', ', '.join(f'{k} {v}' for k, v in sorted(s['outcomes'].items())) or '—'),
        ('time to goal, s (median / p95)',
         f"{num(s['time_to_goal_s']['median'], 1)} / {num(s['time_to_goal_s']['p95'], 1)}"),
        ('path length / optimum (median / p95)',
         f"{num(s['path_over_optimum']['median'], 3)} / "
         f"{num(s['path_over_optimum']['p95'], 3)}"),
        ('replans per run (median)', num(s['replans']['median'], 1)),
        ('replan latency, ms (median of medians / p95 of p95s)',
         f"{num(s['replan_ms']['median'], 1)} / {num(s['replan_ms']['p95'], 1)}"),
        ('controller step, ms (median of medians / p95 of p95s)',
         f"{num(s['controller_step_ms']['median'])} / {num(s['controller_step_ms']['p95'])}"),
        *control_rows(s.get('control')),
        ('sim speed-up, sim s per wall s (median)', num(s['sim_speedup']['median'], 2)),
        ('wall time', f"{num(table['wall_s'] / 60.0, 1)} min, engine {engine} "
                      f"(median run {num(s['run_wall_s']['median'], 0)} s)"),
    ]
    lines = [f"_{info['date']}, {info['cpu']} ({info['cores']} cores), Python {info['python']}, "
             f"commit {info['commit']}_", '',
             f"`{table['command']}`", '',
             f"{table['layout']}", '',
             '| metric | value |', '|---|---|']
    lines += [f'| {name} | {value} |' for name, value in rows]
    if table.get('interrupted'):
        lines += ['', f"**Interrupted** ({table['interrupted']}): the table covers the runs "
                  'that completed.']
    if s['mission_failures']:
        lines += ['', 'Failed missions:', '', '| seed | outcome | reason |', '|---|---|---|']
        lines += [f"| {f['seed']} | {f['outcome']} | {cell(f['reason'])} |"
                  for f in s['mission_failures']]
    if s['incomplete']:
        lines += ['', 'Runs that did not complete:', '', '| seed | reason |', '|---|---|']
        lines += [f"| {f['seed']} | {cell(f['reason'])} |" for f in s['incomplete']]
    retried = [r for r in table['runs'] if r.get('retried_after')]
    if retried:
        lines += ['', 'Runs retried once after a failure on the engine:', '',
                  '| seed | first attempt |', '|---|---|']
        lines += [f"| {r['seed']} | {cell(r['retried_after'])} |" for r in retried]
    return '\n'.join(lines) + '\n'
