"""The node graph of a run: which nodes, with which parameters (no rclpy import).

One description serves both modes: ``processes`` writes each node's parameters to a
ROS params file and starts ``python -m <module>``; ``composed`` passes them as
parameter overrides to node objects on one executor.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from rrtq_sim.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class NodeSpec:
    """One node of the graph."""

    name: str                 # ROS node name, also the log file name
    module: str               # python module with main() and the node class
    cls: str                  # node class name (composed mode)
    params: dict[str, Any]
    subscribes: tuple[str, ...] = ()   # per-step topics it reads (start-up gate)


STEP_TOPICS = ('/clock', '/odom', '/cmd_force', '/controller/state', '/disturbance',
               '/perception/status')


def _flat(a: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def build_graph(scenario: Scenario, speed: float, output: str) -> list[NodeSpec]:
    """The nodes for ``scenario`` (``speed`` 0 = lock-step), recording to ``output``."""
    plant, dist, ctrl = scenario.plant, scenario.disturbance, scenario.controller
    n = plant.n
    sim_time = {'use_sim_time': True}
    controller = NodeSpec('controller', 'rrtq_controller.controller_node', 'ControllerNode', {
        **sim_time, 'variant': str(ctrl.variant), 'horizon': ctrl.horizon,
        'forces': [float(v) for row in ctrl.forces for v in row] or [0.0, 0.0, 0.0],
        'goal': _flat(scenario.goal)}, subscribes=('/clock', '/odom'))
    disturbance_params: dict[str, Any] = {
        **sim_time, 'model': str(dist.model), 'n': n, 'F': _flat(dist.F),
        'amplitude': dist.amplitude, 'frequency': dist.frequency, 'seed': scenario.seed}
    if dist.model == 'worst_case':
        disturbance_params.update(
            gamma=float(dist.gamma), A=_flat(plant.A), B=_flat(plant.B), M=_flat(ctrl.M),
            R=_flat(ctrl.R), P_T=_flat(ctrl.P_T), horizon=ctrl.horizon)
    worst_case = str(dist.model) == 'worst_case'
    disturbance = NodeSpec(
        'disturbance_injector', 'rrtq_sim.disturbance_node', 'DisturbanceNode',
        disturbance_params,
        subscribes=('/clock', '/odom') + (('/controller/state',) if worst_case else ()))
    spawner = NodeSpec('obstacle_spawner', 'rrtq_sim.spawner_node', 'SpawnerNode', {
        **sim_time, 'scenario': scenario.path}, subscribes=('/clock', '/odom'))
    recorder = NodeSpec('recorder', 'rrtq_bringup.recorder_node', 'RecorderNode', {
        'output': output, 'scenario': scenario.path}, subscribes=STEP_TOPICS)
    supervisor = NodeSpec('supervisor', 'rrtq_bringup.supervisor', 'SupervisorNode', {},
                          subscribes=('/odom', '/cmd_force', '/controller/state'))
    others = [recorder, supervisor, controller, disturbance, spawner]
    acks = ['cmd_force', 'controller_state', 'disturbance']
    simulator_reads = ('/cmd_force', '/controller/state', '/disturbance')
    # The first step waits until every reader of the per-step topics is connected,
    # so that no node (and not the recorder) misses step 0.
    wait_for = [f'{topic}:{sum(topic in s.subscribes for s in others) + (topic in simulator_reads)}'
                for topic in STEP_TOPICS]
    simulator = NodeSpec('simulator', 'rrtq_sim.simulator_node', 'SimulatorNode', {
        'n': n, 'dt': ctrl.dt, 'A': _flat(plant.A), 'B': _flat(plant.B), 'F': _flat(dist.F),
        'force_limit': plant.force_limit, 'spring_anchor': str(plant.spring_anchor),
        'start': _flat(scenario.start), 'speed': speed, 'acks': acks,
        'duration': scenario.duration, 'wait_for': wait_for}, subscribes=simulator_reads)
    return [simulator, *others]
