"""The table and the plot of a sweep: one row, one column of the plot, per configuration.

Each configuration's runs are aggregated as the Monte Carlo table aggregates
them (:func:`rrtq_bringup.bench.table.aggregate`): rates over the completed
runs, time and path / optimum over the successful ones.
"""

from __future__ import annotations

import math
import pathlib
from typing import Any

import numpy as np

from rrtq_bringup.bench.table import COMPLETED, cell, control_cell, num, pct

__all__ = ['sweep_markdown', 'sweep_plot']


def sweep_markdown(table: dict[str, Any]) -> str:
    """Header (machine, command, layout), a row per configuration, the runs that failed."""
    info = table['machine']
    lines = [f"_{info['date']}, {info['cpu']} ({info['cores']} cores), Python {info['python']}, "
             f"commit {info['commit']}_", '', f"`{table['command']}`", '',
             f"{table['layout']}", '',
             f"Seeds {table['seeds']} for every configuration; engine {table['engine']}; wall "
             f"time {table['wall_s'] / 60.0:.1f} min.", '',
             '| configuration | runs completed | success (95 % CI) | collisions | out of bounds '
             '| time to goal, s (median) | path / optimum (median / p95) | last-ten leg cost / '
             'Riccati policy, median (runs within 5 % / 10 %) | largest command / limit | '
             'controller step, ms (median of medians) | replans (median) |',
             '|---|---|---|---|---|---|---|---|---|---|---|']
    for conf in table['configurations']:
        s = conf['stats']
        ci = s['success_rate_ci95']
        ci_text = f' ({pct(ci[0])}–{pct(ci[1])})' if ci else ''
        lines.append(
            f"| {cell(conf['label'])} | {s['completed']} of {s['runs']} | "
            f"{pct(s['success_rate'])}{ci_text} | {s['collisions']} | {s.get('out_of_bounds', 0)} | "
            f"{num(s['time_to_goal_s']['median'], 1)} | "
            f"{num(s['path_over_optimum']['median'], 3)} / "
            f"{num(s['path_over_optimum']['p95'], 3)} | {control_cell(s.get('control'))} | "
            f"{num((s.get('control') or {}).get('max_force_over_limit'), 3)} | "
            f"{num(s['controller_step_ms']['median'], 2)} | {num(s['replans']['median'], 1)} |")
    if table.get('interrupted'):
        lines += ['', f"**Interrupted** ({table['interrupted']}): the table covers the runs "
                  'that completed.']
    failed = [(conf['label'], f['seed'], f['outcome'], f['reason'])
              for conf in table['configurations'] for f in conf['stats']['mission_failures']]
    if failed:
        lines += ['', 'Failed missions:', '', '| configuration | seed | outcome | reason |',
                  '|---|---|---|---|']
        lines += [f'| {cell(c)} | {s} | {o} | {cell(r)} |' for c, s, o, r in failed]
    incomplete = [(conf['label'], f['seed'], f['reason'])
                  for conf in table['configurations'] for f in conf['stats']['incomplete']]
    if incomplete:
        lines += ['', 'Runs that did not complete:', '', '| configuration | seed | reason |',
                  '|---|---|---|']
        lines += [f'| {cell(c)} | {s} | {cell(r)} |' for c, s, r in incomplete]
    retried = [(conf['label'], r['seed'], r['retried_after'])
               for conf in table['configurations'] for r in conf['runs'] if r.get('retried_after')]
    if retried:
        lines += ['', 'Runs retried once after a failure on the engine:', '',
                  '| configuration | seed | first attempt |', '|---|---|---|']
        lines += [f'| {cell(c)} | {s} | {cell(why)} |' for c, s, why in retried]
    return '\n'.join(lines) + '\n'


def _ratios(conf: dict[str, Any], key: str) -> list[float]:
    values = []
    for run in conf['runs']:
        if run['status'] != COMPLETED or not run.get('success'):
            continue
        value = run.get(key)
        if value is not None and math.isfinite(value):
            values.append(float(value))
    return values


def sweep_plot(table: dict[str, Any], path: pathlib.Path) -> None:
    """Success rate with its 95 % interval, path / optimum and time to goal per configuration."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    confs = table['configurations']
    x = np.arange(len(confs))
    names = [c['label'].replace(', ', '\n') for c in confs]
    fig, axes = plt.subplots(1, 3, figsize=(max(9.0, 3.0 + 1.6 * len(confs)), 4.2),
                             constrained_layout=True)
    rate = np.array([c['stats']['success_rate'] if c['stats']['success_rate'] is not None
                     else np.nan for c in confs])
    low = np.array([c['stats']['success_rate_ci95'][0] if c['stats']['success_rate_ci95']
                    else np.nan for c in confs])
    high = np.array([c['stats']['success_rate_ci95'][1] if c['stats']['success_rate_ci95']
                     else np.nan for c in confs])
    axes[0].bar(x, 100.0 * rate, color='tab:green', alpha=0.7)
    axes[0].errorbar(x, 100.0 * rate, yerr=100.0 * np.vstack((rate - low, high - rate)),
                     fmt='none', ecolor='k', capsize=4)
    axes[0].set_ylim(0.0, 105.0)
    axes[0].set_ylabel('success, % (95 % Wilson interval)')
    for ax, key, ylabel in ((axes[1], 'path_over_optimum', 'path length / optimum'),
                            (axes[2], 'time_to_goal_s', 'time to goal, s')):
        data = [_ratios(c, key) for c in confs]
        for i, values in enumerate(data):
            if values:
                ax.boxplot([values], positions=[i], widths=0.5, showfliers=True)
                ax.plot(np.full(len(values), i), values, '.', color='tab:blue', alpha=0.5)
        ax.set_ylabel(ylabel + ' (successful runs)')
    for ax in axes:
        ax.set_xticks(x, names, fontsize=8)
        ax.set_xlim(-0.6, len(confs) - 0.4)
        ax.grid(axis='y', alpha=0.3)
    fig.suptitle(f"rrtq bench sweep: {table['scenario']}, seeds {table['seeds']}", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
