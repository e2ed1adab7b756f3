"""Start a run's node graph, watch it, stop it, and write its summary.

``processes`` mode starts one OS process per node (as deployed); ``composed`` puts
every node on one executor in this process. The supervisor node always runs here.
A child process gets SIGTERM from the kernel if this process dies, even by SIGKILL
(``PR_SET_PDEATHSIG``), so no node outlives its orchestrator.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import fcntl
import importlib
import json
import os
import pathlib
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator


from rrtq_bringup.graph import NodeSpec, build_graph, closed_loop
from rrtq_bringup.node_processes import first_failed, start_node, stop_nodes
from rrtq_bringup.mission import MissionConfig, MissionMonitor, Outcome
from rrtq_bringup.run_calibration import write_run_calibration
from rrtq_bringup.scenario import Scenario
from rrtq_common.world import TrueObstacles
from rrtq_controller.config import Variant
from rrtq_controller.drivers import DRIVERS

EXIT_SUCCESS, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
DOMAIN_LOCK_DIR = pathlib.Path('/tmp/rrtq-domains')


class RunMode(enum.StrEnum):
    """How the nodes of a run are hosted (both give the same results)."""

    PROCESSES = 'processes'
    """One OS process per node, as deployed."""
    COMPOSED = 'composed'
    """Every node on one executor in this process (fast Monte Carlo)."""


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """How to run a scenario."""

    out_dir: pathlib.Path
    speed: float = 0.0                 # 0: lock-step as fast as possible; > 0: pace factor
    mode: RunMode = RunMode.PROCESSES
    start_timeout_s: float = 60.0      # wall time allowed before the first step
    stall_timeout_s: float = 20.0      # wall time without a new step before giving up
    live_port: int | None = None       # serve the graph on ws://127.0.0.1:PORT (--live)


class BadInput(Exception):
    """A problem with the user's input: reported with exit code 2, nothing started."""


_LOCK_FDS: dict[int, int] = {}


def lock_fd(domain: int) -> int:
    """The open lock file of a domain held by :func:`domain_id` in this process.

    A run's node processes inherit it, so that the domain stays held until the last of
    them has gone, not only the orchestrator: the nodes of a killed orchestrator take a
    moment to tear down, and a run that took their domain meanwhile would see them.
    """
    return _LOCK_FDS[domain]


@contextlib.contextmanager
def domain_id() -> Iterator[int]:
    """Hold an unused ROS_DOMAIN_ID (1-101) for the run; the lock dies with the process."""
    DOMAIN_LOCK_DIR.mkdir(parents=True, exist_ok=True)
    candidates = list(range(1, 102))
    random.Random(os.getpid()).shuffle(candidates)
    for candidate in candidates:
        handle = open(DOMAIN_LOCK_DIR / f'{candidate}.lock', 'w')  # noqa: SIM115
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _LOCK_FDS[candidate] = handle.fileno()
        try:
            yield candidate
        finally:
            del _LOCK_FDS[candidate]
            handle.close()
        return
    raise RuntimeError('no free ROS_DOMAIN_ID in 1..101')


def ros_env(domain: int) -> dict[str, str]:
    """Environment of every process of a run: DDS on loopback, in the run's domain."""
    return {**os.environ, 'ROS_DOMAIN_ID': str(domain),
            'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
            'RMW_IMPLEMENTATION': os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')}


def mission_config(scenario: Scenario) -> MissionConfig:
    """The mission of ``scenario`` as the supervisor judges it (``rrtq run`` and ``rrtq robot``)."""
    ctrl = scenario.controller
    return MissionConfig(
        goal=(float(scenario.goal[0]), float(scenario.goal[1])),
        goal_tolerance=scenario.goal_tolerance, duration=scenario.duration,
        robot_radius=scenario.robot_radius, bounds=scenario.bounds, dt=ctrl.dt,
        stop_at_goal=ctrl.variant is not Variant.OPEN_LOOP)


def check_supported(scenario: Scenario) -> None:
    """Refuse a controller variant that has no driver yet (exit code 2)."""
    if scenario.controller.variant not in DRIVERS:
        raise BadInput(f'{scenario.path}: controller.variant: '
                       f'{scenario.controller.variant!s} is not implemented yet '
                       f'(available: {", ".join(map(str, DRIVERS))})')


class Run:
    """One run of a scenario: the graph, its supervision, its outputs."""

    def __init__(self, scenario: Scenario, options: RunOptions) -> None:
        self.scenario = scenario
        self.options = options
        self.out = options.out_dir
        self.graph = build_graph(scenario, options.speed, str(self.out / 'run.mcap'),
                                 live_port=options.live_port)
        self.monitor = MissionMonitor(mission_config(scenario),
                                      TrueObstacles.for_scenario(scenario))
        self.stop_requested: str | None = None
        self.failed_node: dict | None = None
        self.children: dict[str, subprocess.Popen] = {}

    # -- lifecycle ----------------------------------------------------------------------
    def execute(self) -> int:
        (self.out / 'logs').mkdir(parents=True, exist_ok=True)
        handlers = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        wall_start = time.monotonic()
        try:
            with domain_id() as domain:
                self.domain = domain
                if self.options.mode is RunMode.PROCESSES:
                    self._run_processes(domain)
                else:
                    self._run_composed(domain)
        finally:
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
        return self._write_summary(time.monotonic() - wall_start)

    def _on_signal(self, signum: int, _frame) -> None:
        self.stop_requested = signal.Signals(signum).name

    def _spin(self, executor, check_children, supervisor) -> None:
        """Spin until the mission ends, a node fails, a signal arrives, or progress stalls."""
        last_step, last_change = -1, time.monotonic()
        self.first_step_wall: float | None = None
        while self.monitor.outcome is Outcome.RUNNING:
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception as exc:  # a node of the composed graph raised
                self._composed_failure(exc)
                break
            now = time.monotonic()
            if self.monitor.steps != last_step:
                if self.first_step_wall is None and self.monitor.steps > 0:
                    self.first_step_wall = now
                last_step, last_change = self.monitor.steps, now
            if self.stop_requested:
                self.monitor.finish(Outcome.INTERRUPTED, f'stopped by {self.stop_requested}')
            elif (failed := check_children()) is not None:
                self.failed_node = failed
                self.monitor.finish(Outcome.NODE_FAILED,
                                    f"node '{failed['node']}' {failed['status']}")
            else:
                limit = (self.options.start_timeout_s if self.monitor.steps == 0
                         else self.options.stall_timeout_s)
                if now - last_change > limit:
                    self.monitor.finish(Outcome.NODE_FAILED,
                                        f'no new odometry for {limit:g} s of wall time '
                                        f'(after {self.monitor.steps} steps): the graph stalled')
        self.last_step_wall = time.monotonic()
        supervisor.pause_simulation()
        # Take what is still in flight: the commands of the last steps may reach the
        # supervisor after the odometry that ended the run, and every node stays up a
        # moment so that the recorder gets (and, if need be, has resent) the last steps.
        deadline = time.monotonic() + 2.0
        settle = time.monotonic() + 0.5
        while (not self.monitor.commands_complete() and time.monotonic() < deadline) \
                or time.monotonic() < settle:
            executor.spin_once(timeout_sec=0.02)

    # -- processes mode -------------------------------------------------------------------
    def _run_processes(self, domain: int) -> None:
        import rclpy
        from rclpy.signals import SignalHandlerOptions
        from rrtq_bringup.supervisor import SupervisorNode
        from rrtq_common.executors import make_executor

        env = ros_env(domain)
        params_dir = self.out / 'params'
        params_dir.mkdir(exist_ok=True)
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain,
                   signal_handler_options=SignalHandlerOptions.NO)
        os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE',)})
        supervisor = SupervisorNode(self.monitor, self.scenario.goal, context=context)
        executor = make_executor(context)
        executor.add_node(supervisor)
        try:
            for spec in self.graph:
                if spec.name != 'supervisor':
                    self.children[spec.name] = self._start_process(spec, params_dir, env)
            self._spin(executor, self._check_children, supervisor)
        finally:
            self._stop_processes()
            executor.remove_node(supervisor)
            supervisor.destroy_node()
            context.try_shutdown()

    def _start_process(self, spec: NodeSpec, params_dir: pathlib.Path,
                       env: dict[str, str]) -> subprocess.Popen:
        return start_node(spec, params_dir, self.out / 'logs', env,
                          pass_fds=(lock_fd(self.domain),))

    def _composed_failure(self, exc: Exception) -> None:
        """A callback raised in composed mode: the run fails naming the node's module."""
        import traceback
        text = ''.join(traceback.format_exception(exc))
        (self.out / 'logs' / 'composed.log').write_text(text)
        frames = traceback.extract_tb(exc.__traceback__)
        node_frames = [f for f in frames if '/rrtq_' in f.filename and 'orchestrator' not in
                       f.filename]
        where = pathlib.Path(node_frames[0].filename).stem if node_frames else 'unknown'
        self.failed_node = {'node': where, 'status': f'raised {type(exc).__name__}: {exc}',
                            'exit_code': None, 'log_tail': text.strip().splitlines()[-15:]}
        self.monitor.finish(Outcome.NODE_FAILED, f"node '{where}' raised {type(exc).__name__}")

    def _check_children(self) -> dict | None:
        return first_failed(self.children, self.out / 'logs')

    def _stop_processes(self) -> None:
        """Stop the graph, the simulator first and the recorder last (it drains)."""
        stop_nodes(self.children, first='simulator')

    # -- composed mode --------------------------------------------------------------------
    def _run_composed(self, domain: int) -> None:
        import rclpy
        from rclpy.parameter import Parameter
        from rclpy.signals import SignalHandlerOptions
        from rrtq_bringup.supervisor import SupervisorNode
        from rrtq_common.executors import make_executor
        from rrtq_common.readiness import announce_when_matched

        os.environ.update(ros_env(domain))
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain,
                   signal_handler_options=SignalHandlerOptions.NO)
        executor = make_executor(context)
        nodes = [SupervisorNode(self.monitor, self.scenario.goal, context=context)]
        try:
            for spec in self.graph:
                if spec.name == 'supervisor':
                    continue
                cls = getattr(importlib.import_module(spec.module), spec.cls)
                overrides = [Parameter(k, value=v) for k, v in spec.params.items()]
                nodes.append(cls(context=context, parameter_overrides=overrides))
                announce_when_matched(nodes[-1])
            for node in nodes:
                executor.add_node(node)
            self._spin(executor, lambda: None, nodes[0])
        finally:
            # Drain what is still queued for the recorder, then destroy the nodes (the
            # recorder last) once nothing spins: a node removed from the EventsExecutor
            # may still have a timer fire (rrtq_common.executors).
            deadline = time.monotonic() + 0.3
            with contextlib.suppress(Exception):  # a failed node's error is already taken
                while time.monotonic() < deadline:
                    executor.spin_once(timeout_sec=0.02)
            for node in nodes:
                if node in executor.get_nodes():
                    executor.remove_node(node)
            executor.shutdown()
            for node in sorted(nodes, key=lambda n: n.get_name() == 'recorder'):
                node.destroy_node()
            context.try_shutdown()

    # -- summary --------------------------------------------------------------------------
    def _write_calibration(self) -> str | None:
        """The run's leg scores beside its recording (a later run's safety.calibration)."""
        recording = self.out / 'run.mcap'
        if not closed_loop(self.scenario) or not recording.exists():
            return None
        try:
            return str(write_run_calibration(self.scenario, recording))
        except Exception as exc:  # noqa: BLE001 - an unreadable partial recording
            print(f'rrtq: no calibration file written ({exc})', file=sys.stderr)
            return None

    def _write_summary(self, wall_s: float) -> int:
        summary = self.monitor.summary()
        first = getattr(self, 'first_step_wall', None)
        stepping_s = (self.last_step_wall - first) if first is not None else 0.0
        summary.update({
            'sim_speedup': (self.monitor.t / stepping_s) if stepping_s > 0 else None,
            'wall_time_s': wall_s,
            'scenario': self.scenario.path, 'name': self.scenario.name,
            'seed': self.scenario.seed, 'mode': self.options.mode,
            'speed': 'max' if self.options.speed == 0 else self.options.speed,
            'ros_domain_id': getattr(self, 'domain', None),
            'failed_node': self.failed_node,
            'recording': str(self.out / 'run.mcap'),
        })
        if self.scenario.controller.variant is Variant.OPEN_LOOP:
            # A scripted plant test has no goal to reach: it succeeds when it runs its
            # course without a collision.
            summary['success'] = self.monitor.outcome is Outcome.DURATION
        code = EXIT_SUCCESS if summary['success'] else EXIT_FAILED
        summary['exit_code'] = code
        summary['calibration'] = self._write_calibration()
        (self.out / 'summary.json').write_text(json.dumps(summary, indent=2) + '\n')
        return code
