"""The local engine of ``rrtq bench``: ``rrtq run`` children on this machine, W at a time.

Also what both engines share: a run's :class:`Job`, the command that runs it, how a
finished run's status is judged, and the progress bar.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import signal
import subprocess
import sys
import time
from collections import deque
from typing import Any, TextIO

from rrtq_bringup.bench.table import COMPLETED
from rrtq_bringup.node_processes import die_with_parent

GRACE_S = 30.0       # wall time an interrupted run gets to write its summary


@dataclasses.dataclass(frozen=True)
class Job:
    """One run: a seed of one configuration."""

    seed: int
    out: pathlib.Path
    scenario: pathlib.Path
    optimum_m: float        # shortest path to the goal's tolerance disc, where a run stops
    config: int = 0         # index of the sweep's configuration


def run_command(scenario: pathlib.Path, out: pathlib.Path) -> list[str]:
    """``rrtq run`` of a bench run: composed and lock-step, so the seed fixes the run."""
    return [sys.executable, '-m', 'rrtq_bringup.cli', 'run', str(scenario), '--out', str(out),
            '--mode', 'composed', '--speed', 'max', '--overwrite']


def start_run(scenario: pathlib.Path, out: pathlib.Path) -> subprocess.Popen:
    """Start ``rrtq run`` with its output in ``out/bench.log``; it dies with this process."""
    log = open(out / 'bench.log', 'wb')  # noqa: SIM115 - the child holds it
    env = {**os.environ, 'ROS_LOG_DIR': str(out / 'logs' / 'ros')}
    # A session of its own: a terminal's Ctrl-C reaches the bench, which passes it on.
    proc = subprocess.Popen(run_command(scenario, out), env=env, stdin=subprocess.DEVNULL,
                            stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                            preexec_fn=die_with_parent)
    log.close()
    return proc


def judge(returncode: int | None, summary: dict | None, timed_out: bool, run_timeout: float,
          log: pathlib.Path) -> str:
    """The status of a finished run: 'completed' or why it did not complete."""
    if timed_out:
        return f'timed out after {run_timeout:g} s of wall time'
    if summary is None or returncode not in (0, 1):
        return (f'rrtq run exited with status {returncode}'
                f'{"" if summary else " without a summary"}; see {log}')
    if summary['outcome'] == 'interrupted':
        return 'interrupted'
    return COMPLETED


def row(job: Job, status: str, summary: dict | None, **extra: Any) -> dict[str, Any]:
    """A run's row of the table."""
    return {'seed': job.seed, 'config': job.config, 'status': status, 'dir': str(job.out),
            'optimum_m': job.optimum_m, 'summary': summary or {}, **extra}


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

    def finished(self, rows: list[dict[str, Any]], running: int, last: str) -> None:
        """Show the bar after a run finished (``rows``: all finished so far)."""
        wins = sum(1 for r in rows if r['status'] == COMPLETED and r['summary']['success'])
        self.show(len(rows), wins, running, last)

    def close(self) -> None:
        if self.tty:
            self.stream.write('\n')
            self.stream.flush()


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    return f'{minutes}m{secs:02d}s' if minutes else f'{secs}s'


def describe(job: Job, status: str, summary: dict | None) -> str:
    """'seed 3: goal_reached', for the progress bar."""
    what = summary['outcome'] if status == COMPLETED and summary else status
    return f'seed {job.seed}: {what}' if not job.config else \
        f'configuration {job.config}, seed {job.seed}: {what}'


class Scheduler:
    """Runs the jobs as ``rrtq run`` children, ``workers`` at a time."""

    def __init__(self, jobs: list[Job], workers: int, run_timeout: float,
                 progress: Progress) -> None:
        self.pending = deque(jobs)
        self.workers = workers
        self.run_timeout = run_timeout
        self.progress = progress
        self.live: dict[subprocess.Popen, tuple[Job, float]] = {}
        self.timed_out: set[Job] = set()
        self.rows: list[dict[str, Any]] = []
        self.stop: str | None = None

    def _on_signal(self, signum: int, _frame) -> None:
        self.stop = signal.Signals(signum).name

    def _start(self, job: Job) -> None:
        self.live[start_run(job.scenario, job.out)] = (job, time.monotonic())

    def _collect(self, proc: subprocess.Popen) -> None:
        job, _ = self.live.pop(proc)
        summary_path = job.out / 'summary.json'
        summary = json.loads(summary_path.read_text()) if summary_path.is_file() else None
        status = judge(proc.returncode, summary, job in self.timed_out, self.run_timeout,
                       job.out / 'bench.log')
        self.rows.append(row(job, status, summary))
        running = len(self.live) + (0 if self.stop else min(len(self.pending),
                                                             self.workers - len(self.live)))
        self.progress.finished(self.rows, running, describe(job, status, summary))

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
                    elif now - started > self.run_timeout and job not in self.timed_out:
                        self.timed_out.add(job)
                        proc.send_signal(signal.SIGINT)
                    elif job in self.timed_out and now - started > self.run_timeout + GRACE_S:
                        proc.kill()
                time.sleep(0.2)
            if self.stop:
                self._interrupt()
        finally:
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
            self.progress.close()
        return self.rows

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
            self.rows.append(row(job, 'not started (interrupted)', None))
        self.pending.clear()
