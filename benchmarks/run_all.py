"""`make bench`: every benchmark, results under benchmarks/results/."""

import pathlib
import subprocess
import sys

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
BENCHMARKS = [[sys.executable, name] for name in (
    'lockstep_speed.py', 'recorder_throughput.py', 'controller_bench.py', 'controller_zero_gain.py',
    'planner_vs_ompl.py', 'vf_lpc_step.py', 'vf_lpc_mismatch.py', 'vf_lpc_guidance.py',
    'margin_step.py', 'safety_step.py', 'margins_offline.py', 'controller_robustness.py',
    'critic_identification.py', 'robot_side.py', 'physical_plant.py',
    'robot_plant_jitter.py')]
# Monte Carlo of the closed loop (rrtq bench): 50 seeds of random layouts on the paper
# scenario, on every core; about 25 minutes on 2 cores.
BENCHMARKS.append([str(ROOT / 'scripts/rrtq'), 'bench', str(ROOT / 'scenarios/rrtqx_paper.yaml'),
                   '--seeds', '50', '--runs', str(ROOT / 'runs/bench/rrtqx-paper'),
                   '--out', str(HERE / 'results'), '--overwrite'])

for command in BENCHMARKS:
    print(f'== {" ".join(pathlib.Path(part).name for part in command[1:3])}', flush=True)
    subprocess.run(command, check=True, cwd=HERE)
