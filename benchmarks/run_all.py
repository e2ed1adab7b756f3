"""`make bench`: every benchmark, results under benchmarks/results/, then docs/benchmarks.md.

    python benchmarks/run_all.py              # every benchmark (hours on 2 cores), then the page
    python benchmarks/run_all.py --doc-only   # only docs/benchmarks.md, from the current results

Each benchmark writes ``benchmarks/results/<name>.md`` (its table under a line with the date
and the machine) and ``.json``; ``docs/benchmarks.md`` is assembled from those files, a section
per benchmark with the command that regenerates it. After running one benchmark by hand, rerun
with ``--doc-only``.
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
import re
import subprocess
import sys

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / 'results'
DOC = ROOT / 'docs' / 'benchmarks.md'


@dataclasses.dataclass(frozen=True)
class Benchmark:
    """One benchmark: its result file's name, its section in the page, how it is run."""

    name: str
    """Its result files: ``results/<name>.md`` and ``.json``."""
    group: str
    title: str
    what: str
    script: str = ''
    """Its program in ``benchmarks/`` (default: ``<name>.py``)."""
    command: tuple[str, ...] = ()
    """Instead of a program: the command, run from ``benchmarks/``."""

    def argv(self) -> list[str]:
        return list(self.command) or [sys.executable, self.script or f'{self.name}.py']

    def shown(self) -> str:
        """The command as a user types it at the repository's root (after scripts/env.sh)."""
        if not self.command:
            return f'python benchmarks/{self.script or self.name + ".py"}'
        return ' '.join(part.replace(str(ROOT) + '/', '') for part in self.command)


def _rrtq(*args: str) -> tuple[str, ...]:
    return (str(ROOT / 'scripts' / 'rrtq'), *args)


# In the order `make bench` runs them; the page groups them by `group`, in GROUPS' order.
BENCHMARKS = [
    Benchmark('lockstep_speed', 'Speed', 'Lock-step speed',
              'Steps per second of the graph in lock-step against a ping-pong floor, composed '
              'and in processes, on both executors.'),
    Benchmark('recorder_throughput', 'Speed', 'Recorder throughput',
              'Messages per second the MCAP recorder takes, in process and from another '
              'process.'),
    Benchmark('controller', 'Controller', 'Controller against the Riccati optimum',
              'The Q-learning controller on the rover without a spring, leg by leg, against '
              'the finite-horizon Riccati optimum (no ROS).', script='controller_bench.py'),
    Benchmark('controller_zero_gain', 'Controller', 'Learning from a zero initial gain',
              'The same from no initial gain: when the time basis widens, gain error and leg '
              'cost at leg 20.'),
    Benchmark('planner_vs_ompl', 'Planner', 'RRT^X against OMPL',
              "RRT^X as `rrtq plan` runs it against OMPL's RRT*, Informed RRT* and BIT* on the "
              'same collision checks: path cost over the optimum, repairs, iteration time.'),
    Benchmark('vf_lpc_step', 'VF-LPC', 'VF-LPC control step',
              'CPU time of one receding-horizon actor-critic step.'),
    Benchmark('vf_lpc_mismatch', 'VF-LPC', 'VF-LPC under model mismatch, offline',
              'Identified at 40 kg, run at 60-80 kg through acceleration bumps, with and '
              'without the online sparse GP (no ROS).'),
    Benchmark('vf_lpc_guidance', 'VF-LPC', 'The guiding vector field',
              'Rollouts of the guidance along RRT^X paths: goal, v²κ against the limit, '
              'clearance.'),
    Benchmark('vf_lpc_bench', 'VF-LPC', 'VF-LPC side by side with RRT-QX, in the graph',
              'A `--set controller.variant=nominal,vf_lpc` sweep of random layouts.'),
    Benchmark('vf_lpc_graph_mismatch', 'VF-LPC', 'VF-LPC under model mismatch, in the graph',
              '`scenarios/vf_lpc_mismatch.yaml` with the GP and without.'),
    Benchmark('margin_step', 'Safety margins', 'Margin policy step cost',
              'Milliseconds per step of each margin policy, replayed over a recorded mission.'),
    Benchmark('safety_step', 'Safety margins', 'Safety step on a forest',
              'The safety node\'s step on forest_100 (286 trees): nearest obstacle, the cast '
              'ahead, republication.'),
    Benchmark('margins_offline', 'Safety margins', 'Margin coverage, offline',
              'Legs whose deviation stayed within the margin in force, per mode, first and '
              'calibrated second mission (no ROS).'),
    Benchmark('margins_closed_loop', 'Safety margins', 'Margins in the closed loop',
              'The calibrated learned bound (from a calibration pooled from other seeds), the '
              'uncalibrated one and running_max on five scenarios with gaps and disturbance '
              'bumps and on random layouts; coverage checked from the recordings. The '
              'uncalibrated and running_max benches ran at d711af1 (nothing they run has '
              'changed since), the calibration at fa6a643 (flown without one: the later '
              'changes act only with one), the calibrated rows at 24899da, tabulated from '
              'their recordings at bc2d16b (`--tabulate`).'),
    Benchmark('controller_robustness', 'Controller', 'Random plants from the defaults',
              '40 random plants, 30 legs each, no initial gain, blind to the disturbance: cost '
              'against the true Riccati policy flown through the same disturbance.'),
    Benchmark('critic_identification', 'Controller', 'How well the critic identifies a gain',
              "A held policy's greedy gain identified by the critic, per plant and probing "
              'level.'),
    Benchmark('defaults_only', 'Controller', 'Closed loop from the defaults, seven plants',
              'No controller key, no initial gain, undisturbed: goals, collisions, last-ten leg '
              'cost against the optimum and the Riccati policy.'),
    Benchmark('robot_side', 'Controller', 'The robot side blind to its disturbance',
              'Twelve rows of disturbances, plants, odometry noise and actuation delay, the '
              'robot reading only its odometry, commands and perception. Six of the rows with '
              'the experimental push feed-forward on, its cancelling law (docs/observer.md §6): '
              'results/robot_side_push_feedforward.md.'),
    Benchmark('push_feedforward', 'Controller', 'The robot side with the LQ push feed-forward',
              'The rows of the robot-side benchmark with the opt-in LQ-optimal push '
              'feed-forward on (`controller.push_feedforward: true`, docs/observer.md §7), to '
              'set against the same rows without it.'),
    Benchmark('riccati_gain', 'Controller', 'Learned against the optimal feedback',
              'A robot-side row flown twice on the same layouts: learned from the defaults, '
              'and with the actor held at the Riccati gain of the true plant. Where the gain '
              'meets the row and learning does not, the learner fails the row.'),
    Benchmark('physical_plant', 'Bring your own robot', 'MuJoCo plant and laser scan',
              'The MuJoCo plant at three Coulomb frictions, and scan against polygon '
              'perception.'),
    Benchmark('robot_plant_jitter', 'Bring your own robot', '`rrtq robot` against `rrtq plant`',
              'The control period at real time, on the machine as it is and under load.'),
    # Monte Carlo of the closed loop (rrtq bench): 50 seeds of random layouts on the paper
    # scenario, on every core; about 25 minutes on 2 cores.
    Benchmark('monte_carlo', 'Closed loop', 'Monte Carlo of the paper scenario',
              '50 random layouts of the paper scenario: success, collisions, time to goal, '
              'path against the visibility-graph optimum, replanning latency.',
              command=_rrtq('bench', str(ROOT / 'scenarios/rrtqx_paper.yaml'), '--seeds', '50',
                            '--runs', str(ROOT / 'runs/bench/rrtqx-paper'), '--out',
                            str(RESULTS), '--overwrite')),
]
GROUPS = ['Closed loop', 'Planner', 'Controller', 'Safety margins', 'Bring your own robot',
          'VF-LPC', 'Speed']
LINK = re.compile(r'(!?\[[^\]]*\]\()([^)\s]+)\)')


def anchor(title: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r'[^\w\- ]', '', title.strip().lower()).replace(' ', '-')


def section(bench: Benchmark) -> str:
    """The page's section of one benchmark: its result file, headings demoted, links rebased."""
    source = RESULTS / f'{bench.name}.md'
    text = source.read_text().strip()
    text = re.sub(r'^(#{1,4}) ', lambda m: '#' * min(len(m.group(1)) + 3, 6) + ' ', text,
                  flags=re.M)
    text = LINK.sub(lambda m: m.group(1) + (
        m.group(2) if re.match(r'[a-z]+://|#|/', m.group(2))
        else f'../benchmarks/results/{m.group(2)}') + ')', text)
    return '\n'.join([
        f'### {bench.title}', '', bench.what, '',
        f'Regenerate: `{bench.shown()}` (results: '
        f'[benchmarks/results/{bench.name}.md](../benchmarks/results/{bench.name}.md) and '
        '`.json`).', '', text, ''])


def page() -> str:
    """docs/benchmarks.md, from every benchmark's current result file."""
    missing = [b.name for b in BENCHMARKS if not (RESULTS / f'{b.name}.md').is_file()]
    if missing:
        raise SystemExit(f'no result file for {", ".join(missing)} in {RESULTS}')
    lines = ['# Benchmarks', '',
             '<!-- Written by `python benchmarks/run_all.py --doc-only` from '
             'benchmarks/results/*.md; edit those files or this script, not this page. -->', '',
             'Every current benchmark table. `make bench` reruns them all (several hours on 2 '
             'cores) and rewrites this page; each section names the command that regenerates '
             'its table alone (from the repository\'s root, after `source scripts/env.sh`; then '
             '`python benchmarks/run_all.py --doc-only` rewrites this page). The line in '
             'italics under each command is the date, the machine and the commit the table was '
             'measured on. The machines are shared 2-core virtual machines: absolute times are '
             'noisy. One-off experiments are written up in [notes/](notes/README.md).', '']
    for group in GROUPS:
        lines.append(f'- {group}: ' + ', '.join(
            f'[{b.title}](#{anchor(b.title)})' for b in BENCHMARKS if b.group == group))
    for group in GROUPS:
        lines += ['', f'## {group}', '']
        lines += [section(b) for b in BENCHMARKS if b.group == group]
    return '\n'.join(lines).rstrip() + '\n'


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--doc-only', action='store_true',
                    help='only assemble docs/benchmarks.md from the current results')
    args = ap.parse_args()
    if not args.doc_only:
        for bench in BENCHMARKS:
            print(f'== {bench.name}', flush=True)
            subprocess.run(bench.argv(), check=True, cwd=HERE)
    DOC.write_text(page())
    print(f'wrote {DOC.relative_to(ROOT)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
