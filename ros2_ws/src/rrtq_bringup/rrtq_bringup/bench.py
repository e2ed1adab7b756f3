"""``rrtq bench``: Monte Carlo over seeds and random obstacle layouts.

For each seed the base scenario gets a random obstacle layout
(:mod:`rrtq_bringup.bench_layouts`), written to ``RUNS/seed-NNN/scenario.yaml``, and
runs there as ``rrtq run --mode composed --speed max`` (lock-step: the seed fixes the
run), ``--workers`` at a time, each in a process of its own. A progress bar on stderr
counts runs, successes and the time left; Ctrl-C or SIGTERM interrupts the runs in
flight (each ends its recording and summary) and writes the table of what completed.

The table (:mod:`rrtq_bringup.bench_table`) goes to ``OUT/monte_carlo.md`` and
``OUT/monte_carlo.json``. Exit code 0 when every run completed, whatever its mission
outcome; 1 when a run crashed or timed out; 2 on bad input (nothing started); 130 when
interrupted.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable
from typing import Any, TextIO

import yaml

from rrtq_bringup.bench_layouts import (Layout, LayoutConfig, LayoutError, generate_layout,
                                        layout_scenario)
from rrtq_bringup.bench_table import COMPLETED, aggregate, machine, markdown
from rrtq_bringup.orchestrator import BadInput, _die_with_parent, check_supported
from rrtq_bringup.scenario import Scenario, ScenarioError, load_scenario

EXIT_OK, EXIT_INCOMPLETE, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
ROOT = pathlib.Path(os.environ.get('RRTQ_ROOT', pathlib.Path(__file__).resolve().parents[4]))
GRACE_S = 30.0       # wall time an interrupted run gets to write its summary


@dataclasses.dataclass(frozen=True)
class Job:
    """One seed's run."""

    seed: int
    out: pathlib.Path
    scenario: pathlib.Path
    optimum_m: float        # shortest path to the goal's tolerance disc, where a run stops


def _count(low: int) -> Callable[[str], int]:
    """An argparse type: an integer >= ``low``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None
        if value < low:
            raise argparse.ArgumentTypeError(f'must be >= {low}, got {value}')
        return value
    return parse


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='rrtq bench', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario', nargs='?', type=pathlib.Path,
                        default=ROOT / 'scenarios' / 'rrtqx_paper.yaml',
                        help='base scenario: bounds, start, goal, robot, plant, controller, '
                        'planner (its obstacles are replaced; default: the paper scenario)')
    parser.add_argument('--seeds', type=_count(1), default=50, help='number of seeds (50)')
    parser.add_argument('--first-seed', type=_count(0), default=0, help='first seed (0)')
    parser.add_argument('--workers', type=_count(1), default=os.cpu_count() or 1,
                        help='runs at a time (default: the number of cores)')
    parser.add_argument('--obstacles', type=_count(0), default=LayoutConfig.obstacles,
                        help=f'obstacles per layout ({LayoutConfig.obstacles})')
    parser.add_argument('--out', type=pathlib.Path,
                        help='directory of monte_carlo.md and .json (default: the runs '
                        'directory)')
    parser.add_argument('--runs', type=pathlib.Path,
                        help='directory of the runs, one seed-NNN/ each '
                        '(default: runs/bench/<scenario name>)')
    parser.add_argument('--run-timeout', type=_count(1), default=1800,
                        help='wall seconds after which a run is stopped as timed out (1800)')
    parser.add_argument('--overwrite', action='store_true',
                        help='replace the seed directories of an earlier bench')
    return parser


def _prepare(base: Scenario, document: dict[str, Any], seeds: range, runs: pathlib.Path,
             config: LayoutConfig) -> list[Job]:
    """Draw every seed's layout, then write its scenario file and check it as a run would."""
    layouts: list[Layout] = [generate_layout(base, seed, config) for seed in seeds]
    jobs = []
    for layout in layouts:
        out = runs / f'seed-{layout.seed:03d}'
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir(parents=True)
        path = out / 'scenario.yaml'
        doc = layout_scenario(document, layout, f'{base.name}-seed-{layout.seed:03d}')
        path.write_text(f'# rrtq bench: {base.path} with the random layout of seed '
                        f'{layout.seed}\n'
                        + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
        (out / 'layout.json').write_text(json.dumps({
            'seed': layout.seed, 'attempts': layout.attempts,
            'optimum_m': layout.optimum.length, 'optimum_path': layout.optimum.path.tolist(),
            'route_m': layout.route.length, 'config': dataclasses.asdict(config)},
            indent=1) + '\n')
        load_scenario(path)
        to_disc = max(0.0, layout.optimum.length - base.goal_tolerance)
        jobs.append(Job(layout.seed, out, path, to_disc))
    return jobs


class Progress:
    """A one-line progress bar on a terminal; a line per finished run elsewhere."""

    def __init__(self, total: int, stream: TextIO = sys.stderr, width: int = 28) -> None:
        self.total, self.stream, self.width = total, stream, width
        self.start = time.monotonic()
        self.tty = stream.isatty()

    def show(self, done: int, successes: int, running: int, last: str = '') -> None:
        elapsed = time.monotonic() - self.start
        eta = elapsed / done * (self.total - done) if done else None
        filled = int(self.width * done / self.total)
        line = (f'bench [{"#" * filled}{"." * (self.width - filled)}] {done}/{self.total} '
                f'ok {successes}, {running} running, {_clock(elapsed)} elapsed, ETA '
                f'{_clock(eta) if eta is not None else "?"}')
        if self.tty:
            self.stream.write('\r' + line + '\x1b[K')
        elif last:
            self.stream.write(f'{line} ({last})\n')
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write('\n')
            self.stream.flush()


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    return f'{minutes}m{secs:02d}s' if minutes else f'{secs}s'


class Scheduler:
    """Runs the jobs as ``rrtq run`` children, ``workers`` at a time."""

    def __init__(self, jobs: list[Job], workers: int, run_timeout: float,
                 progress: Progress) -> None:
        self.pending = deque(jobs)
        self.workers = workers
        self.run_timeout = run_timeout
        self.progress = progress
        self.live: dict[subprocess.Popen, tuple[Job, float]] = {}
        self.timed_out: set[int] = set()
        self.rows: list[dict[str, Any]] = []
        self.stop: str | None = None

    def _on_signal(self, signum: int, _frame) -> None:
        self.stop = signal.Signals(signum).name

    def _start(self, job: Job) -> None:
        log = open(job.out / 'bench.log', 'wb')  # noqa: SIM115 - the child holds it
        env = {**os.environ, 'ROS_LOG_DIR': str(job.out / 'logs' / 'ros')}
        cmd = [sys.executable, '-m', 'rrtq_bringup.cli', 'run', str(job.scenario),
               '--out', str(job.out), '--mode', 'composed', '--speed', 'max', '--overwrite']
        # A session of its own: a terminal's Ctrl-C reaches the bench, which passes it on.
        proc = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True,
                                preexec_fn=_die_with_parent)
        log.close()
        self.live[proc] = (job, time.monotonic())

    def _collect(self, proc: subprocess.Popen) -> None:
        job, _ = self.live.pop(proc)
        summary_path = job.out / 'summary.json'
        summary = json.loads(summary_path.read_text()) if summary_path.is_file() else None
        if job.seed in self.timed_out:
            status = f'timed out after {self.run_timeout:g} s of wall time'
        elif summary is None or proc.returncode not in (0, 1):
            status = (f'rrtq run exited with status {proc.returncode}'
                      f'{"" if summary else " without a summary"}; see {job.out / "bench.log"}')
        elif summary['outcome'] == 'interrupted':
            status = 'interrupted'
        else:
            status = COMPLETED
        self.rows.append({'seed': job.seed, 'status': status, 'dir': str(job.out),
                          'optimum_m': job.optimum_m, 'summary': summary or {}})
        done = len(self.rows)
        wins = sum(1 for r in self.rows if r['status'] == COMPLETED and r['summary']['success'])
        what = summary['outcome'] if status == COMPLETED and summary else status
        running = len(self.live) + (0 if self.stop else min(len(self.pending),
                                                             self.workers - len(self.live)))
        self.progress.show(done, wins, running, f'seed {job.seed}: {what}')

    def run(self) -> list[dict[str, Any]]:
        handlers = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            self.progress.show(0, 0, 0)
            while (self.pending or self.live) and not self.stop:
                while self.pending and len(self.live) < self.workers:
                    self._start(self.pending.popleft())
                now = time.monotonic()
                for proc, (job, started) in list(self.live.items()):
                    if proc.poll() is not None:
                        self._collect(proc)
                    elif now - started > self.run_timeout and job.seed not in self.timed_out:
                        self.timed_out.add(job.seed)
                        proc.send_signal(signal.SIGINT)
                    elif job.seed in self.timed_out and now - started > self.run_timeout \
                            + GRACE_S:
                        proc.kill()
                time.sleep(0.2)
            if self.stop:
                self._interrupt()
        finally:
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
            self.progress.close()
        return sorted(self.rows, key=lambda r: r['seed'])

    def _interrupt(self) -> None:
        """Stop the runs in flight (they write their summaries); the rest never start."""
        for proc in self.live:
            proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + GRACE_S
        for proc in list(self.live):
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            self._collect(proc)
        for job in self.pending:
            self.rows.append({'seed': job.seed, 'status': 'not started (interrupted)',
                              'dir': str(job.out), 'optimum_m': job.optimum_m, 'summary': {}})
        self.pending.clear()


def _run_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per-run lines of the JSON table."""
    keys = ('success', 'collided', 'outcome', 'reason', 'time_to_goal_s', 'path_length_m',
            'min_clearance_m', 'replans', 'replan_ms', 'controller_step_ms', 'sim_speedup',
            'sim_time_s', 'wall_time_s')
    out = []
    for row in rows:
        s = row['summary']
        ratio = (s['path_length_m'] / row['optimum_m']
                 if row['status'] == COMPLETED and s.get('success') else None)
        out.append({'seed': row['seed'], 'status': row['status'], 'dir': row['dir'],
                    'optimum_m': row['optimum_m'], 'path_over_optimum': ratio,
                    **{k: s.get(k) for k in keys}})
    return out


def _layout_text(config: LayoutConfig, base: Scenario) -> str:
    known = int(config.obstacles * config.known_fraction)
    return (f'Base scenario `{base.path}` ({base.name}); per seed {config.obstacles} random '
            f'obstacles (rectangles and circles, {config.size[0]:g}–{config.size[1]:g} m): '
            f'{known} known from t = 0 about the start–goal line, {config.obstacles - known} '
            'appearing about the route, timed to appear within perception range; an '
            'obstacle never appears within '
            f'{base.appear_clearance:g} m of the robot (`appear_clearance`). Composed mode, '
            'lock-step. Optimum: shortest path with every obstacle present, grown by the '
            f'robot radius ({base.robot_radius:g} m), on the visibility graph, to within '
            f"the goal tolerance ({base.goal_tolerance:g} m) where a run stops.")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = _parser().parse_args(argv)
    config = LayoutConfig(obstacles=args.obstacles)
    try:
        base = load_scenario(args.scenario)
        check_supported(base)
        if str(base.controller.variant) == 'open_loop':
            raise BadInput(f'{base.path}: controller.variant: open_loop has no goal to reach; '
                           'the bench needs the planner and a learning controller')
        document = yaml.safe_load(args.scenario.read_text())
        runs = args.runs or pathlib.Path('runs') / 'bench' / base.name
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        earlier = [runs / f'seed-{s:03d}' for s in seeds if (runs / f'seed-{s:03d}').exists()]
        if earlier and not args.overwrite:
            raise BadInput(f'{earlier[0]} exists (an earlier bench); choose another --runs or '
                           'pass --overwrite')
        jobs = _prepare(base, document, seeds, runs, config)
    except (ScenarioError, BadInput, LayoutError) as exc:
        print(f'rrtq bench: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    out = args.out or runs
    print(f'rrtq bench: {len(jobs)} seeds of {base.name} ({args.obstacles} obstacles each), '
          f'{args.workers} workers -> {runs}', file=sys.stderr)
    started = time.monotonic()
    scheduler = Scheduler(jobs, args.workers, float(args.run_timeout), Progress(len(jobs)))
    rows = scheduler.run()
    table = {
        'machine': machine(pathlib.Path(__file__).resolve().parent),
        'command': 'rrtq bench ' + shlex.join(argv),
        'scenario': str(args.scenario), 'seeds': f'{seeds.start}–{seeds.stop - 1}',
        'workers': args.workers, 'wall_s': time.monotonic() - started,
        'layout': _layout_text(config, base), 'layout_config': dataclasses.asdict(config),
        'interrupted': scheduler.stop, 'stats': aggregate(rows), 'runs': _run_rows(rows),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / 'monte_carlo.json').write_text(json.dumps(table, indent=2) + '\n')
    (out / 'monte_carlo.md').write_text(markdown(table))
    stats = table['stats']
    print(json.dumps({k: stats[k] for k in ('runs', 'completed', 'success_rate',
                                             'collision_rate')}))
    print(f'rrtq bench: table in {out / "monte_carlo.md"}', file=sys.stderr)
    if scheduler.stop:
        return EXIT_INTERRUPTED
    return EXIT_OK if stats['completed'] == stats['runs'] else EXIT_INCOMPLETE


if __name__ == '__main__':
    sys.exit(main())
