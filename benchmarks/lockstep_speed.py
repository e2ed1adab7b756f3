"""Lock-step speed of the plant-only graph: simulated seconds per wall second, both modes.

Runs ``rrtq run`` on scenarios/plant_only.yaml (60 s of sim time) a few times in each
mode and reports the median ``sim_speedup`` (sim time / wall time from the first step
to the last; start-up excluded) and steps per second.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile

from common import ROOT, save

REPEATS = 3


def main() -> None:
    scenario = (ROOT / 'scenarios/plant_only.yaml').read_text().replace('duration: 30.0',
                                                                        'duration: 60.0')
    results: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = f'{tmp}/bench.yaml'
        open(path, 'w').write(scenario)
        for mode in ('processes', 'composed'):
            speedups = []
            for i in range(REPEATS):
                out = f'{tmp}/{mode}{i}'
                subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', path, '--out', out,
                                '--mode', mode], check=True, capture_output=True)
                summary = json.load(open(f'{out}/summary.json'))
                speedups.append(summary['sim_speedup'])
                print(f'{mode} run {i}: {summary["sim_speedup"]:.2f}x', file=sys.stderr)
            results[mode] = {'sim_speedup_median': statistics.median(speedups),
                             'sim_speedup_runs': speedups,
                             'steps_per_s_median': statistics.median(speedups) / 0.05}
    table = ('| mode | sim s per wall s (median of 3) | steps/s |\n|---|---|---|\n' +
             '\n'.join(f"| {m} | {r['sim_speedup_median']:.1f} | {r['steps_per_s_median']:.0f} |"
                       for m, r in results.items()))
    save('lockstep_speed', results, table)


if __name__ == '__main__':
    main()
