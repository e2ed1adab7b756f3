"""The nodes as OS processes: started from their specs, watched, stopped in order.

What ``rrtq run --mode processes`` (:mod:`rrtq_bringup.orchestrator`) and ``rrtq robot``
(:mod:`rrtq_bringup.robot`) share: each node runs as ``python -m MODULE`` with its parameters
in a YAML file, its output in ``LOGS/NAME.log``, in its own session, and dies with its parent.
"""

from __future__ import annotations

import ctypes
import pathlib
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence

import yaml

from rrtq_bringup.graph import NodeSpec

__all__ = ['die_with_parent', 'start_node', 'first_failed', 'stop_nodes']


def die_with_parent() -> None:
    """In the child before exec: SIGTERM when the parent dies (PR_SET_PDEATHSIG)."""
    libc = ctypes.CDLL('libc.so.6', use_errno=True)
    libc.prctl(1, signal.SIGTERM)


def start_node(spec: NodeSpec, params_dir: pathlib.Path, logs: pathlib.Path,
               env: Mapping[str, str], pass_fds: Sequence[int] = ()) -> subprocess.Popen:
    """Start ``spec`` as a process: its parameters in ``params_dir``, its output in ``logs``."""
    params_file = params_dir / f'{spec.name}.yaml'
    params_file.write_text(yaml.safe_dump({spec.name: {'ros__parameters': spec.params}}))
    log = open(logs / f'{spec.name}.log', 'wb')  # noqa: SIM115  (the child holds it)
    cmd = [sys.executable, '-m', spec.module, '--ros-args', '--params-file', str(params_file)]
    return subprocess.Popen(cmd, env=dict(env), stdout=log, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, preexec_fn=die_with_parent,
                            start_new_session=True, pass_fds=tuple(pass_fds))


def first_failed(children: Mapping[str, subprocess.Popen], logs: pathlib.Path) -> dict | None:
    """The first node process that has ended (with its status and log tail), or None."""
    for name, proc in children.items():
        code = proc.poll()
        if code is not None:
            status = (f'was killed by {signal.Signals(-code).name}' if code < 0
                      else f'exited with status {code}')
            log = (logs / f'{name}.log').read_text(errors='replace')
            return {'node': name, 'status': status, 'exit_code': code,
                    'log_tail': log.strip().splitlines()[-15:]}
    return None


def stop_nodes(children: Mapping[str, subprocess.Popen], first: str,
               timeout_s: float = 10.0) -> None:
    """SIGINT every node, ``first`` first and the recorder last (it drains); kill a laggard."""
    for name in sorted(children, key=lambda n: (n == 'recorder', n != first)):
        proc = children[name]
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
