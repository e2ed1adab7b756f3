"""The Ray engine of ``rrtq bench`` (``--engine ray [--address ADDR]``).

Each run is a Ray task asking for one CPU, so Ray starts it on whichever node has a
free core.  The task writes the run's scenario into a temporary directory of its
node, runs ``rrtq run`` there (composed, lock-step: the same as the local engine,
so the same seed gives the same run), takes the ``ROS_DOMAIN_ID`` lock of that host
as every ``rrtq run`` does (``/tmp/rrtq-domains``: unique per host), and returns the
run directory (recording, summary, logs) as a tar archive, which the driver unpacks
into its own runs directory.  Nothing needs to be shared between the machines but
the code: every node runs the same commit of the repository, set up with ``make
setup`` and with ``scripts/env.sh`` sourced before ``ray start`` (a task refuses to
run on a node whose commit differs from the driver's).

Without ``--address`` the bench starts a private Ray instance on this machine with
``--workers`` CPUs, its servers on 127.0.0.1 only, and stops it at the end.

Failures: a task whose worker process dies, or whose node leaves the cluster, is
submitted once more (Ray's own retries are off, so the bench knows and reports
it); a second failure fails that run only.  Ctrl-C (or SIGTERM) cancels every task:
a queued one never starts; a running one's worker is ended and Ray ends the
worker's ``rrtq run`` with it, leaving on that node, under ``/tmp/rrtq-bench/``, a
recording readable up to its last chunk and no summary.  The table lists them as
interrupted; nothing of the bench keeps running.
"""

from __future__ import annotations

import io
import json
import logging
import os
import pathlib
import shutil
import signal
import socket
import tarfile
import tempfile
import time
from typing import Any

from rrtq_bringup.bench.local_engine import GRACE_S, Job, Progress, describe, judge, row, start_run
from rrtq_bringup.bench.table import machine

__all__ = ['RayEngine', 'RayUnavailable', 'cluster_text', 'run_task']

POLL_S = 0.5         # how often a task looks at its run, the driver at its tasks


class RayUnavailable(Exception):
    """Ray is not installed, or the cluster cannot be reached (bad input, exit 2)."""


def _pack(directory: pathlib.Path) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode='w') as tar:
        for item in sorted(directory.iterdir()):
            if item.name != 'scenario.yaml':   # the driver wrote it
                tar.add(item, arcname=item.name)
    return buffer.getvalue()


def run_task(spec: dict[str, Any]) -> dict[str, Any]:
    """The body of a Ray task: one ``rrtq run`` on this node, its directory returned.

    Parameters
    ----------
    spec : dict
        ``bench`` (the driver's id), ``name`` (the run's), ``scenario`` (its YAML
        text), ``commit`` (the driver's), ``run_timeout`` (s).

    Returns
    -------
    dict
        ``returncode``, ``timed_out``, ``archive`` (tar bytes of the run directory),
        ``node``, ``pid``.

    Notes
    -----
    The task makes no Ray call while it runs: a task blocked in ``ray.get`` lends
    its CPU to the next queued task, which would put two runs on one core.
    """
    here = machine(pathlib.Path(__file__).resolve().parent)['commit']
    if here != spec['commit']:
        raise RuntimeError(f'node {socket.gethostname()} runs commit {here}, the driver '
                           f'{spec["commit"]}: check out the same commit on every node')
    # One directory per bench and run: a retry on the same node clears what the
    # attempt whose worker died left behind.
    work = pathlib.Path(tempfile.gettempdir(), 'rrtq-bench', f'{spec["bench"]}-{spec["name"]}')
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    try:
        scenario = work / 'scenario.yaml'
        scenario.write_text(spec['scenario'])
        proc = start_run(scenario, work)
        started = time.monotonic()
        timed_out = False
        while proc.poll() is None:
            time.sleep(POLL_S)
            elapsed = time.monotonic() - started
            if not timed_out and elapsed > spec['run_timeout']:
                timed_out = True
                proc.send_signal(signal.SIGINT)
            elif timed_out and elapsed > spec['run_timeout'] + GRACE_S:
                proc.kill()
        return {'returncode': proc.returncode, 'timed_out': timed_out,
                'archive': _pack(work), 'node': socket.gethostname(), 'pid': os.getpid()}
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _token_available() -> bool:
    """Whether this user has a Ray cluster token where Ray looks for one."""
    path = os.environ.get('RAY_AUTH_TOKEN_PATH')
    return ('RAY_AUTH_TOKEN' in os.environ or (path is not None and os.path.isfile(path))
            or (pathlib.Path.home() / '.ray' / 'auth_token').is_file())


def _connect(address: str | None, workers: int):
    """Import Ray and join the cluster at ``address``, or start a private local one."""
    host = (address or '127.0.0.1').rsplit(':', 1)[0]
    if host in ('127.0.0.1', 'localhost', '::1', '[::1]'):
        # Read when ray is imported.  Ray otherwise swaps a loopback address for the
        # machine's network address; with it the node's address is 127.0.0.1, so the
        # servers of a private instance listen on the loopback interface only and a
        # driver finds a head that was started that way.
        os.environ['RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER'] = '0'
    if address is not None and 'RAY_AUTH_MODE' not in os.environ and _token_available():
        # Ray turns token authentication on by itself only for address 'auto'; a head
        # started with it on (Ray's default) refuses a driver that joins without it.
        os.environ['RAY_AUTH_MODE'] = 'token'
    try:
        import ray
    except ImportError as exc:
        raise RayUnavailable(f'--engine ray needs the ray package ({exc}); run make setup'
                             ) from None
    try:
        if address is None:
            ray.init(address='local', num_cpus=workers, include_dashboard=False,
                     log_to_driver=False, logging_level=logging.WARNING)
        else:
            ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        raise RayUnavailable(f'--address {address}: cannot join the Ray cluster ({exc})'
                             ) from None
    return ray


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f'{type(exc).__name__}: {text[0] if text else ""}'.strip()


class RayEngine:
    """Runs the jobs as Ray tasks; the same rows as :class:`.local_engine.Scheduler`."""

    def __init__(self, jobs: list[Job], address: str | None, workers: int,
                 run_timeout: float, progress: Progress) -> None:
        self.jobs = jobs
        self.address = address
        self.workers = workers
        self.run_timeout = run_timeout
        self.progress = progress
        self.rows: list[dict[str, Any]] = []
        self.stop: str | None = None
        self.ray = _connect(address, workers)
        resources = self.ray.cluster_resources()
        self.cluster = {'nodes': len([n for n in self.ray.nodes() if n.get('Alive')]),
                        'cpus': resources.get('CPU', 0.0)}

    def _on_signal(self, signum: int, _frame) -> None:
        self.stop = signal.Signals(signum).name

    def run(self) -> list[dict[str, Any]]:
        ray = self.ray
        # Ray's own retries stay off: the bench retries once itself, and reports it.
        task = ray.remote(num_cpus=1, max_retries=0)(run_task)
        commit = machine(pathlib.Path(__file__).resolve().parent)['commit']
        bench = f'{socket.gethostname()}-{os.getpid()}-{int(time.time())}'
        specs = {job: {'bench': bench, 'name': job.scenario.parent.name if not job.config else
                       f'cfg{job.config:02d}-{job.scenario.parent.name}',
                       'scenario': job.scenario.read_text(), 'commit': commit,
                       'run_timeout': self.run_timeout} for job in self.jobs}
        live = {task.remote(specs[job]): job for job in self.jobs}
        failed_once: dict[Job, str] = {}
        handlers = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            self.progress.show(0, 0, len(live))
            while live and not self.stop:
                ready, _ = ray.wait(list(live), num_returns=1, timeout=POLL_S)
                for ref in ready:
                    job = live.pop(ref)
                    try:
                        result = ray.get(ref)
                    except ray.exceptions.RayError as exc:
                        why = _first_line(exc)
                        if job not in failed_once:
                            failed_once[job] = why
                            live[task.remote(specs[job])] = job
                            continue
                        self.rows.append(row(job, f'failed on Ray twice: {failed_once[job]}; '
                                             f'then {why}', None, attempts=2,
                                             retried_after=failed_once[job]))
                    else:
                        self.rows.append(self._collect(job, result, failed_once.get(job)))
                    last = self.rows[-1]
                    self.progress.finished(self.rows, len(live),
                                           describe(job, last['status'], last['summary']))
            for ref, job in live.items():
                ray.cancel(ref, force=True)
                self.rows.append(row(job, 'interrupted (task cancelled; a run that had started '
                                     'left its recording on its node, /tmp/rrtq-bench/)',
                                     None))
        finally:
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
            self.progress.close()
            ray.shutdown()
        return self.rows

    def _collect(self, job: Job, result: dict[str, Any], first: str | None) -> dict[str, Any]:
        """Unpack a finished task's run directory into ``job.out``; its row."""
        attempts = {'attempts': 2 if first else 1, 'retried_after': first}
        with tarfile.open(fileobj=io.BytesIO(result['archive']), mode='r') as tar:
            tar.extractall(job.out, filter='data')
        summary_path = job.out / 'summary.json'
        summary = None
        if summary_path.is_file():
            summary = json.loads(summary_path.read_text())
            # Where the run lives now, and where it ran.
            summary.update({'scenario': str(job.scenario),
                            'recording': str(job.out / 'run.mcap'),
                            'ray_node': result['node']})
            summary_path.write_text(json.dumps(summary, indent=2) + '\n')
        status = judge(result['returncode'], summary, result['timed_out'], self.run_timeout,
                       job.out / 'bench.log')
        return row(job, status, summary, node=result['node'], **attempts)


def cluster_text(engine: RayEngine) -> str:
    """'ray (private, 2 CPUs)' or 'ray (ADDR: 3 nodes, 24 CPUs)'."""
    where = 'private instance on 127.0.0.1' if engine.address is None else engine.address
    return (f"ray ({where}: {engine.cluster['nodes']} node(s), "
            f"{engine.cluster['cpus']:g} CPUs)")

