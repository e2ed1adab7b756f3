"""`make bench`: every benchmark, results under benchmarks/results/."""

import pathlib
import subprocess
import sys

HERE = pathlib.Path(__file__).resolve().parent
BENCHMARKS = ['lockstep_speed.py', 'recorder_throughput.py', 'controller_bench.py', 'planner_vs_ompl.py']

for name in BENCHMARKS:
    print(f'== {name}', flush=True)
    subprocess.run([sys.executable, str(HERE / name)], check=True, cwd=HERE)
