"""Shared bits of the benchmarks: machine description and result files."""

from __future__ import annotations

import datetime
import json
import os
import pathlib
import platform
import subprocess

RESULTS = pathlib.Path(__file__).resolve().parent / 'results'
ROOT = RESULTS.parents[1]


def machine() -> dict:
    cpu = ''
    try:
        for line in open('/proc/cpuinfo'):
            if line.startswith('model name'):
                cpu = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    return {'cpu': cpu, 'cores': os.cpu_count(), 'python': platform.python_version(),
            'kernel': platform.release(),
            'date': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC'),
            'commit': subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=ROOT,
                                     capture_output=True, text=True).stdout.strip()}


def save(name: str, results: dict, table: str) -> None:
    """Write ``results/<name>.json`` and ``results/<name>.md`` (the table, with the machine)."""
    RESULTS.mkdir(exist_ok=True)
    info = machine()
    (RESULTS / f'{name}.json').write_text(json.dumps({'machine': info, **results}, indent=2)
                                          + '\n')
    header = (f"_{info['date']}, {info['cpu']} ({info['cores']} cores), Python "
              f"{info['python']}, commit {info['commit']}_\n\n")
    (RESULTS / f'{name}.md').write_text(header + table + '\n')
    print(header + table)
