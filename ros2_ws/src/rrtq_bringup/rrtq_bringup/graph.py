"""The node graph of a run: which nodes, with which parameters (no rclpy import).

One description serves both modes: ``processes`` writes each node's parameters to a
ROS params file and starts ``python -m <module>``; ``composed`` passes them as
parameter overrides to node objects on one executor.

Lock-step chain of one step k (each arrow: "waits for, stamped t_k"):
spawner (odom) -> safety (perception status, controller state of k-1) -> planner
(safety status) -> controller (planner stats; disturbance of k-1 when robust) ->
disturbance injector (controller state, worst case only) -> simulator (command,
controller state, disturbance) -> step k+1. Outputs published only on change
(detected map, augmented set, plan) are named by the stamp in the status that
follows them, so a reader knows when to wait for one.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from rrtq_sim.scenario import Scenario

STEP_TOPICS = ('/clock', '/odom', '/cmd_force', '/controller/state', '/disturbance',
               '/perception/status', '/safety/status', '/planner/stats')


@dataclasses.dataclass(frozen=True)
class NodeSpec:
    """One node of the graph."""

    name: str                 # ROS node name, also the log file name
    module: str               # python module with main() and the node class
    cls: str                  # node class name (composed mode)
    params: dict[str, Any]
    subscribes: tuple[str, ...] = ()   # per-step topics it reads (start-up gate)


def _flat(a: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def _optional(value: float | None) -> float:
    return -1.0 if value is None else float(value)


def closed_loop(scenario: Scenario) -> bool:
    """A learning controller needs the planner and the safety node."""
    return str(scenario.controller.variant) != 'open_loop'


def build_graph(scenario: Scenario, speed: float, output: str) -> list[NodeSpec]:
    """The nodes for ``scenario`` (``speed`` 0 = lock-step), recording to ``output``."""
    plant, dist, ctrl = scenario.plant, scenario.disturbance, scenario.controller
    n, m = plant.n, plant.m
    lockstep = speed == 0.0
    loop = closed_loop(scenario)
    robust = str(ctrl.variant) == 'robust'
    worst_case = str(dist.model) == 'worst_case'
    sim_time = {'use_sim_time': True}
    clock = ('/clock',)

    def chain(*keys: str) -> list[str]:
        return list(keys) if lockstep and keys else ['']

    controller_params: dict[str, Any] = {
        **sim_time, 'variant': str(ctrl.variant), 'n': n, 'm': m, 'q': dist.q,
        'horizon': ctrl.horizon, 'dt': ctrl.dt, 'rho': ctrl.rho, 'seed': scenario.seed,
        'chain': chain(*(['planner_stats'] if loop else []) + (['disturbance'] if robust
                                                               else []))}
    if loop:
        controller_params.update(
            M=_flat(ctrl.M), R=_flat(ctrl.R), P_T=_flat(ctrl.P_T),
            alpha_c=_optional(ctrl.alpha_c), alpha_a=_optional(ctrl.alpha_a),
            alpha_d=_optional(ctrl.alpha_d), gamma=float(ctrl.gamma or 3.0),
            critic_law=ctrl.critic_law, actor_law=ctrl.actor_law,
            initial_gain=[0.0] if ctrl.initial_gain is None else _flat(ctrl.initial_gain),
            probing_std=_optional(ctrl.probing_std),
            probing_decay=_optional(ctrl.probing_decay))
    else:
        controller_params.update(
            forces=[float(v) for row in ctrl.forces for v in row] or [0.0, 0.0, 0.0],
            goal=_flat(scenario.goal))
    controller = NodeSpec('controller', 'rrtq_controller.controller_node', 'ControllerNode',
                          controller_params,
                          subscribes=clock + ('/odom',) + (('/planner/stats',) if loop else ())
                          + (('/disturbance',) if robust else ()))
    disturbance_params: dict[str, Any] = {
        **sim_time, 'model': str(dist.model), 'n': n, 'F': _flat(dist.F),
        'amplitude': dist.amplitude, 'frequency': dist.frequency, 'seed': scenario.seed}
    if worst_case:
        disturbance_params.update(
            gamma=float(dist.gamma), A=_flat(plant.A), B=_flat(plant.B), M=_flat(ctrl.M),
            R=_flat(ctrl.R), P_T=_flat(ctrl.P_T), horizon=ctrl.horizon)
    disturbance = NodeSpec(
        'disturbance_injector', 'rrtq_sim.disturbance_node', 'DisturbanceNode',
        disturbance_params,
        subscribes=clock + ('/odom',) + (('/controller/state',) if worst_case else ()))
    spawner = NodeSpec('obstacle_spawner', 'rrtq_sim.spawner_node', 'SpawnerNode', {
        **sim_time, 'scenario': scenario.path}, subscribes=clock + ('/odom',))
    published = STEP_TOPICS if loop else STEP_TOPICS[:6]
    recorder = NodeSpec('recorder', 'rrtq_bringup.recorder_node', 'RecorderNode', {
        'output': output, 'scenario': scenario.path}, subscribes=published)
    supervisor = NodeSpec('supervisor', 'rrtq_bringup.supervisor', 'SupervisorNode', {},
                          subscribes=('/odom', '/cmd_force', '/controller/state')
                          + (('/planner/stats',) if loop else ()))
    others = [recorder, supervisor, controller, disturbance, spawner]
    if loop:
        planner_cfg = scenario.planner
        (xmin, xmax), (ymin, ymax) = scenario.bounds
        others.append(NodeSpec('planner', 'rrtq_planner.planner_node', 'PlannerNode', {
            **sim_time, 'bounds': [float(xmin), float(xmax), float(ymin), float(ymax)],
            'steer_distance': float(planner_cfg.get('steer_distance', 5.0)),
            'epsilon': float(planner_cfg.get('epsilon', 0.0)),
            'iterations_per_step': int(planner_cfg.get('iterations_per_step', 30)),
            'max_nodes': int(planner_cfg.get('max_nodes', 3000)),
            'cycle_budget_ms': float(planner_cfg.get('cycle_budget_ms', 10.0)),
            'tree_period_s': float(planner_cfg.get('tree_period_s', 1.0)),
            'seed': scenario.seed, 'dt': ctrl.dt, 'chain': chain('safety_status')},
            subscribes=clock + ('/odom', '/safety/status')))
        others.append(NodeSpec('safety', 'rrtq_planner.safety_node', 'SafetyNode', {
            **sim_time, 'scenario': scenario.path, 'dt': ctrl.dt,
            'growth_threshold': float(planner_cfg.get('growth_threshold', 0.05)),
            'chain': chain('perception_status', 'controller_state')},
            subscribes=clock + ('/odom', '/perception/status', '/controller/state')))
    acks = ['cmd_force', 'controller_state', 'disturbance']
    simulator_reads = ('/cmd_force', '/controller/state', '/disturbance')
    # The first step waits until every reader of the per-step topics is connected,
    # so that no node (and not the recorder) misses step 0.
    wait_for = [f'{topic}:{sum(topic in s.subscribes for s in others) + (topic in simulator_reads)}'
                for topic in published]
    simulator = NodeSpec('simulator', 'rrtq_sim.simulator_node', 'SimulatorNode', {
        'n': n, 'dt': ctrl.dt, 'A': _flat(plant.A), 'B': _flat(plant.B), 'F': _flat(dist.F),
        'force_limit': plant.force_limit, 'spring_anchor': str(plant.spring_anchor),
        'start': _flat(scenario.start), 'speed': speed, 'acks': acks,
        'duration': scenario.duration, 'wait_for': wait_for}, subscribes=simulator_reads)
    return [simulator, *others]
