"""``rrtq robot``: the robot's side of a scenario alone, against an external plant.

The planner, the controller (free-running: :mod:`rrtq_controller.free_running_node`), the
safety node and the recorder, one OS process each, as ``rrtq run`` starts them but without
simulator, injector, spawner or lock-step gate: whatever publishes /odom and the perception
(/obstacles/detected, /perception/status) is the plant, and /cmd_force goes to it. That
may be ``rrtq plant`` (:mod:`rrtq_bringup.plant`) or a robot.

Time: ``--clock auto`` (the default) waits for the plant, a publisher of /clock or /odom,
then runs the nodes on sim time when /clock has a publisher (by ``clock_wait_s`` after
/odom's appeared), on wall time otherwise; ``--clock sim`` and ``--clock wall`` decide
without waiting. The mission is judged from /odom (the robot has no truth: no collision
judgement here, the bounds on the measured position), its time the odometry's stamps on
sim time, the wall time since the first odometry on wall time. It ends at the goal, at the
scenario's duration, on Ctrl-C or SIGTERM, when a node fails, or when the odometry stops
for ``odometry_timeout_s`` of run time (outcome ``odometry_lost``: the plant vanished).

ROS_DOMAIN_ID is the environment's (the plant must share it); ROS_AUTOMATIC_DISCOVERY_RANGE
stays LOCALHOST unless the user set it.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import os
import pathlib
import signal
import subprocess
import time


from rrtq_bringup.graph import NodeSpec, build_graph
from rrtq_bringup.mission import MissionClock, MissionMonitor, Outcome
from rrtq_bringup.node_processes import first_failed, start_node, stop_nodes
from rrtq_bringup.orchestrator import EXIT_FAILED, EXIT_SUCCESS, mission_config
from rrtq_bringup.scenario import Scenario
from rrtq_common import topics
from rrtq_common.run import READY_PARAMETER
from rrtq_common.world import TrueObstacles
from rrtq_controller.config import Variant
from rrtq_controller.staleness import FreeRunConfig

ROBOT_NODES = ('controller', 'planner', 'safety', 'obstacle_mapper', 'recorder', 'live')
"""The nodes of ``rrtq run``'s graph that ``rrtq robot`` starts (live with ``--live``; the
mapper with ``perception: {source: scan}``, turning the plant's ``/scan`` into the map)."""
SIM_TIME_NODES = ('controller', 'planner', 'safety', 'obstacle_mapper')
LOST_STALE_MULTIPLE = 10.0
"""The default give-up time: this many times the controller's staleness limit."""
LOST_WALL_FLOOR_S = 1.0
"""Wall time without odometry below which the run never gives up (s). At 5 x real time
the default give-up time is 0.3 s of wall time, which a busy machine's scheduler can take
from one process; the controller has commanded zero since 3 dt either way, so a plant that
hiccups is waited for and only one that vanished ends the run."""
DRAIN_CALLBACKS = 200
"""Callbacks taken at most before the odometry is judged lost (what queued while starved)."""


class ClockSource(enum.StrEnum):
    """Where the robot's nodes take their time from."""

    AUTO = 'auto'
    """Sim time if a /clock publisher shows up within ``clock_wait_s``, else wall time."""
    SIM = 'sim'
    WALL = 'wall'


@dataclasses.dataclass(frozen=True)
class RobotOptions:
    """How to run the robot's side."""

    out_dir: pathlib.Path
    live_port: int | None = None
    clock: ClockSource = ClockSource.AUTO
    clock_wait_s: float = 2.0            # auto: wall time after /odom's publisher to wait
                                         # for one of /clock
    odometry_timeout_s: float | None = None   # run time; None: LOST_STALE_MULTIPLE x stale
    start_timeout_s: float = 60.0        # wall time to wait for the first odometry


def robot_graph(scenario: Scenario, output: str, sim_time: bool,
                live_port: int | None = None) -> list[NodeSpec]:
    """The robot's nodes of ``scenario`` (paced), recording to ``output``."""
    specs = []
    for spec in build_graph(scenario, 1.0, output, live_port=live_port):
        if spec.name not in ROBOT_NODES:
            continue
        params = {k: v for k, v in spec.params.items() if k != READY_PARAMETER}
        if spec.name in SIM_TIME_NODES:
            params['use_sim_time'] = sim_time
        if spec.name == 'controller':
            spec = dataclasses.replace(spec, module='rrtq_controller.free_running_node',
                                       cls='FreeRunningControllerNode')
        specs.append(dataclasses.replace(spec, params=params))
    return specs


def robot_env() -> dict[str, str]:
    """The nodes' environment: the user's domain, loopback discovery unless the user chose."""
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    return env


class RobotRun:
    """One run of the robot's side: its processes, the mission, the summary."""

    def __init__(self, scenario: Scenario, options: RobotOptions) -> None:
        self.scenario = scenario
        self.options = options
        self.out = options.out_dir
        # No truth on the robot's side: the mission is judged from /odom alone.
        self.monitor = MissionMonitor(mission_config(scenario), TrueObstacles([]))
        stale = FreeRunConfig().stale_steps * scenario.controller.dt
        self.odometry_timeout_s = (options.odometry_timeout_s if options.odometry_timeout_s
                                   else LOST_STALE_MULTIPLE * stale)
        self.clock = MissionClock(self.odometry_timeout_s)
        self.stop_requested: str | None = None
        self.failed_node: dict | None = None
        self.children: dict[str, subprocess.Popen] = {}

    # -- lifecycle ----------------------------------------------------------------------
    def execute(self) -> int:
        (self.out / 'logs').mkdir(parents=True, exist_ok=True)
        handlers = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        wall_start = time.monotonic()
        try:
            self._run()
        finally:
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
        return self._write_summary(time.monotonic() - wall_start)

    def _on_signal(self, signum: int, _frame) -> None:
        self.stop_requested = signal.Signals(signum).name

    def _run(self) -> None:
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        from rrtq_bringup.robot_supervisor import RobotSupervisorNode
        from rrtq_common.executors import make_executor

        env = robot_env()
        os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE',
                                               'RMW_IMPLEMENTATION')})
        self.domain = int(env.get('ROS_DOMAIN_ID', '0') or 0)
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=self.domain,
                   signal_handler_options=SignalHandlerOptions.NO)
        supervisor = RobotSupervisorNode(self.monitor, self.scenario.goal, self.clock,
                                         context=context)
        executor = make_executor(context)
        executor.add_node(supervisor)
        try:
            self.clock.sim_time = self._choose_clock(executor, supervisor)
            graph = robot_graph(self.scenario, str(self.out / 'run.mcap'), self.clock.sim_time,
                                self.options.live_port)
            params_dir = self.out / 'params'
            params_dir.mkdir(exist_ok=True)
            # The controller last: its /cmd_force is what a waiting plant starts on, and by
            # then the recorder records and the planner has its goal.
            for spec in sorted(graph, key=lambda s: s.name == 'controller'):
                if spec.name == 'controller':
                    self._wait_for_nodes(executor, supervisor, [s.name for s in graph
                                                                if s.name != 'controller'])
                self.children[spec.name] = self._start_process(spec, params_dir, env)
            self._spin(executor)
        finally:
            self._stop_processes()
            executor.remove_node(supervisor)
            supervisor.destroy_node()
            context.try_shutdown()

    def _choose_clock(self, executor, supervisor) -> bool:
        """Sim time or wall time (``--clock auto``: sim when the plant has a /clock publisher).

        Waits for the plant: a publisher of /clock or of /odom (up to the start timeout).
        With /odom's publisher there and no /clock publisher ``clock_wait_s`` later, the
        plant runs on wall time.
        """
        if self.options.clock is not ClockSource.AUTO:
            return self.options.clock is ClockSource.SIM
        start = time.monotonic()
        odom_seen: float | None = None
        while not self.stop_requested and time.monotonic() - start < self.options.start_timeout_s:
            if supervisor.count_publishers(topics.CLOCK) > 0:
                return True
            now = time.monotonic()
            if odom_seen is None and supervisor.count_publishers(topics.ODOM) > 0:
                odom_seen = now
            if odom_seen is not None and now - odom_seen > self.options.clock_wait_s:
                return False
            executor.spin_once(timeout_sec=0.05)
        return False

    def _wait_for_nodes(self, executor, supervisor, names: list[str]) -> None:
        """Spin until the nodes ``names`` are in the graph (or a signal, or a node failed)."""
        deadline = time.monotonic() + self.options.start_timeout_s
        while (not set(names) <= set(supervisor.get_node_names()) and not self.stop_requested
               and self._check_children() is None and time.monotonic() < deadline):
            executor.spin_once(timeout_sec=0.05)

    def _spin(self, executor) -> None:
        started = time.monotonic()
        while self.monitor.outcome is Outcome.RUNNING:
            executor.spin_once(timeout_sec=0.02)
            now = time.monotonic()
            if self.stop_requested:
                self.monitor.finish(Outcome.INTERRUPTED, f'stopped by {self.stop_requested}')
            elif (failed := self._check_children()) is not None:
                self.failed_node = failed
                self.monitor.finish(Outcome.NODE_FAILED,
                                    f"node '{failed['node']}' {failed['status']}")
            elif self.clock.watch.last_stamp is None:
                if now - started > self.options.start_timeout_s:
                    self.monitor.finish(Outcome.ODOMETRY_LOST,
                                        f'odometry lost: no odometry on {topics.ODOM} within '
                                        f'{self.options.start_timeout_s:g} s of wall time')
            elif self._odometry_lost(executor):
                self.monitor.finish(
                    Outcome.ODOMETRY_LOST,
                    f'odometry lost: none for more than {self.odometry_timeout_s:g} s of run '
                    f'time after t={self.monitor.t:.2f} s (the plant stopped publishing '
                    f'{topics.ODOM})')
        # The recorder takes what is still in flight before the nodes stop.
        settle = time.monotonic() + 0.5
        while time.monotonic() < settle:
            executor.spin_once(timeout_sec=0.02)

    def _odometry_lost(self, executor) -> bool:
        """No odometry for the give-up time of run time and the wall floor, after a drain.

        A supervisor starved by the scheduler finds the odometry that queued meanwhile
        before it judges: the callbacks already waiting are taken first.
        """
        if not self._past_give_up(time.monotonic()):
            return False
        for _ in range(DRAIN_CALLBACKS):
            last = self.clock.watch.last_stamp
            executor.spin_once(timeout_sec=0.0)
            if self.clock.watch.last_stamp != last:
                return False
        return self._past_give_up(time.monotonic())

    def _past_give_up(self, now: float) -> bool:
        watch = self.clock.watch
        return (watch.age(now) > self.odometry_timeout_s
                and watch.wall_since_last(now) > LOST_WALL_FLOOR_S)

    # -- processes ----------------------------------------------------------------------
    def _start_process(self, spec: NodeSpec, params_dir: pathlib.Path,
                       env: dict[str, str]) -> subprocess.Popen:
        return start_node(spec, params_dir, self.out / 'logs', env)

    def _check_children(self) -> dict | None:
        return first_failed(self.children, self.out / 'logs')

    def _stop_processes(self) -> None:
        """Stop the nodes, the controller first (no command outlives the run), the recorder last."""
        stop_nodes(self.children, first='controller')

    # -- summary --------------------------------------------------------------------------
    def _write_summary(self, wall_s: float) -> int:
        summary = self.monitor.summary()
        summary.update({
            'wall_time_s': wall_s,
            'scenario': self.scenario.path, 'name': self.scenario.name,
            'seed': self.scenario.seed, 'mode': 'robot',
            'clock': 'sim' if self.clock.sim_time else 'wall',
            'odometry_timeout_s': self.odometry_timeout_s,
            'ros_domain_id': getattr(self, 'domain', None),
            'failed_node': self.failed_node,
            'recording': str(self.out / 'run.mcap'),
        })
        if self.scenario.controller.variant is Variant.OPEN_LOOP:
            summary['success'] = self.monitor.outcome is Outcome.DURATION
        code = EXIT_SUCCESS if summary['success'] else EXIT_FAILED
        summary['exit_code'] = code
        (self.out / 'summary.json').write_text(json.dumps(summary, indent=2) + '\n')
        return code
