"""``rrtq plant``: a scenario's plant alone, as a process a robot can drive.

The simulator, the disturbance injector and the obstacle spawner of ``rrtq run``'s graph on
one executor in one process, paced at ``speed`` × real time: it publishes /clock, /odom
(and /odom/truth), the perception (/obstacles/detected, /perception/status), /disturbance,
/obstacles/truth and /referee/status, and reads /cmd_force (and /controller/state, whose leg
target anchors the ``leg_target`` spring). No lock-step: each step takes the newest
command. A command not renewed for more than ``command_timeout_s`` of sim time counts as
missing, and zero force is held until the next one (:class:`CommandHold`).

The plant takes its first step once a /cmd_force publisher is there (then 0.5 s more, for
discovery to finish): started before its robot, it waits at t = 0 with its /clock
publisher up (which ``rrtq robot`` takes as the sign to run on sim time). It runs until
the scenario's duration (0: for ever), Ctrl-C or SIGTERM. ROS_DOMAIN_ID is the
environment's; ROS_AUTOMATIC_DISCOVERY_RANGE stays LOCALHOST unless the user set it.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import signal
import sys
import time

from rrtq_bringup.graph import NodeSpec, build_graph
from rrtq_bringup.scenario import Scenario
from rrtq_common.run import READY_PARAMETER
from rrtq_common.settings import check, setting, to_parameters

PLANT_NODES = ('simulator', 'disturbance_injector', 'obstacle_spawner')
EXIT_OK, EXIT_NODE_FAILED = 0, 1
LINGER_S = 1.0
"""Wall time the plant stays up after its last step, so that its last messages get out."""


@dataclasses.dataclass(frozen=True)
class PlantProcessConfig:
    """The stand-alone simulator's own settings."""

    command_timeout_s: float = setting(0.5, unit='s', low=0.0, low_open=True, doc='sim time '
                                       'after the last /cmd_force after which the plant holds '
                                       'zero force')

    def __post_init__(self) -> None:
        check(self)


class CommandHold:
    """Whether the held command has expired (no rclpy).

    Parameters
    ----------
    timeout_ns : int
        Sim time (ns) after the last command's arrival from which it counts as missing.
    """

    def __init__(self, timeout_ns: int) -> None:
        self.timeout_ns = timeout_ns
        self._last_ns: int | None = None
        self._expired = False

    def received(self, now_ns: int) -> bool:
        """A command arrived at sim time ``now_ns``; True when it ends a missing spell."""
        self._last_ns = now_ns
        resumed, self._expired = self._expired, False
        return resumed

    def expired(self, now_ns: int) -> bool:
        """True once (at the first step) when the command has gone missing at ``now_ns``.

        Before the first command there is nothing to expire: the plant holds zero anyway.
        """
        if self._last_ns is None or self._expired or now_ns - self._last_ns <= self.timeout_ns:
            return False
        self._expired = True
        return True


def plant_graph(scenario: Scenario, speed: float,
                config: PlantProcessConfig | None = None) -> list[NodeSpec]:
    """The plant's nodes of ``scenario`` paced at ``speed`` (> 0) × real time."""
    if not speed > 0.0:
        raise ValueError(f'the plant runs paced: speed must be > 0, got {speed}')
    specs = []
    for spec in build_graph(scenario, speed, ''):
        if spec.name not in PLANT_NODES:
            continue
        params = {k: v for k, v in spec.params.items() if k != READY_PARAMETER}
        if spec.name == 'simulator':
            # Wait for a commander only: the robot's readers are not this process's to count
            # (wait_for and ready_from fall back to their defaults, none).
            params = {k: v for k, v in params.items() if k not in ('wait_for', 'ready_from')}
            params.update(acks=['cmd_force'], **to_parameters(config or PlantProcessConfig()))
            spec = dataclasses.replace(spec, module='rrtq_bringup.standalone_simulator',
                                       cls='StandaloneSimulatorNode')
        specs.append(dataclasses.replace(spec, params=params))
    return specs


def run_plant(scenario: Scenario, speed: float, config: PlantProcessConfig | None = None) -> int:
    """Run the plant until its duration or a signal; the exit code."""
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from rrtq_common.executors import make_executor

    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    domain = int(os.environ.get('ROS_DOMAIN_ID', '0') or 0)
    stop: list[str] = []
    handlers = {s: signal.signal(s, lambda signum, _f: stop.append(signal.Signals(signum).name))
                for s in (signal.SIGINT, signal.SIGTERM)}
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    executor = make_executor(context)
    nodes = []
    code = EXIT_OK
    try:
        for spec in plant_graph(scenario, speed, config):
            cls = getattr(importlib.import_module(spec.module), spec.cls)
            overrides = [Parameter(k, value=v) for k, v in spec.params.items()]
            nodes.append(cls(context=context, parameter_overrides=overrides))
            executor.add_node(nodes[-1])
        simulator = nodes[0]
        print(f'rrtq: plant {scenario.name} at {speed:g} x real time on ROS_DOMAIN_ID={domain}; '
              'waiting for a /cmd_force publisher', file=sys.stderr, flush=True)
        announced = False
        while not stop and not simulator.sim.finished:
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception as exc:  # noqa: BLE001 - a node raised: report and stop
                print(f'rrtq: plant node raised {type(exc).__name__}: {exc}', file=sys.stderr)
                code = EXIT_NODE_FAILED
                break
            if simulator.started and not announced:
                announced = True
                print('rrtq: plant stepping', file=sys.stderr, flush=True)
        end = time.monotonic() + (LINGER_S if not stop and code == EXIT_OK else 0.0)
        while time.monotonic() < end and not stop:
            executor.spin_once(timeout_sec=0.05)
        why = f'stopped by {stop[0]}' if stop else f'duration {scenario.duration:g} s elapsed'
        print(f'rrtq: plant {why} at t={simulator.sim.now_ns * 1e-9:.2f} s', file=sys.stderr)
    finally:
        for node in nodes:
            executor.remove_node(node)
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    return code
