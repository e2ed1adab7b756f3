"""The node graph of a run: which nodes, with which parameters (no rclpy import).

One description serves both modes: ``processes`` writes each node's parameters to a
ROS params file and starts ``python -m <module>``; ``composed`` passes them as
parameter overrides to node objects on one executor. The parameters are the scenario's
settings dataclasses as they are (:func:`rrtq_common.settings.to_parameters`); each
node declares its parameters from the same dataclasses.

Lock-step chain of one step k (each arrow: "waits for, stamped t_k"):
spawner (true odometry) -> safety (perception status, controller state of k-1) -> planner
(safety status) -> controller (planner stats; the safety status, for the keep-off;
disturbance of k-1 when it learns from it) ->
disturbance injector (controller state, worst case only) -> simulator (command,
controller state, disturbance) -> step k+1. Outputs published only on change
(detected map, augmented set, plan) are named by the stamp in the status that
follows them, so a reader knows when to wait for one. With ``planner.guidance.mode: gvf``
the planner also publishes /guidance/reference every step; the vf_lpc controller waits
for it (and for the augmented set it names) instead of following the plan.

With ``perception.source: scan`` the spawner publishes /scan (on the steps that carry one)
instead of the robot's map, and the robot's obstacle mapper (/odom, /scan) writes
/obstacles/detected and /perception/status in its place: spawner -> mapper -> safety.

The simulator publishes the robot's measurement on /odom and the true state on
/odom/truth: the robot's side (controller, planner, safety) reads /odom only, the
simulator's side (spawner, injector, supervisor) /odom/truth only. The spawner's
/referee/status is recorded and read by no node.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from rrtq_bringup.recording import RecorderConfig
from rrtq_bringup.scenario import Scenario, worst_case_game
from rrtq_bringup.viz import LiveConfig, VizConfig
from rrtq_common import topics
from rrtq_common.run import READY_PARAMETER, Dimensions, RunConfig
from rrtq_common.scan import PerceptionSource
from rrtq_common.settings import to_parameters
from rrtq_common.world_yaml import WorldSource
from rrtq_controller.config import Variant
from rrtq_planner.obstacle_map import MapperConfig
from rrtq_planner.guidance import GuidanceMode
from rrtq_sim.disturbance import DisturbanceModel
from rrtq_sim.plant import PlantModel
from rrtq_sim.scan import ScanWorld
from rrtq_sim.simulation import SimulatorConfig

STEP_TOPICS = (topics.CLOCK, topics.ODOM, topics.ODOM_TRUTH, topics.CMD_FORCE,
               topics.CONTROLLER_STATE, topics.DISTURBANCE, topics.PERCEPTION_STATUS,
               topics.REFEREE_STATUS, topics.SAFETY_STATUS, topics.PLANNER_STATS)
# The per-step topics of the closed loop only (no planner or safety node in open loop).
LOOP_TOPICS = (topics.SAFETY_STATUS, topics.PLANNER_STATS)
# What the simulator reads: the inputs it holds (and the acknowledgements of a step).
SIMULATOR_READS = (topics.CMD_FORCE, topics.CONTROLLER_STATE, topics.DISTURBANCE)


@dataclasses.dataclass(frozen=True)
class NodeSpec:
    """One node of the graph."""

    name: str                 # ROS node name, also the log file name
    module: str               # python module with main() and the node class
    cls: str                  # node class name (composed mode)
    params: dict[str, Any]
    subscribes: tuple[str, ...] = ()   # per-step topics it reads (start-up gate)
    publishes: tuple[str, ...] = ()    # per-step topics it writes (start-up handshake)


def closed_loop(scenario: Scenario) -> bool:
    """A learning controller needs the planner and the safety node."""
    return scenario.controller.variant is not Variant.OPEN_LOOP


def build_graph(scenario: Scenario, speed: float, output: str,
                live_port: int | None = None) -> list[NodeSpec]:
    """The nodes for ``scenario`` (``speed`` 0 = lock-step), recording to ``output``.

    ``live_port``: also serve the graph on ws://127.0.0.1:PORT (``rrtq run --live``).
    """
    plant, dist, ctrl = scenario.plant, scenario.disturbance, scenario.controller
    loop = closed_loop(scenario)
    vf_lpc = ctrl.variant is Variant.VF_LPC
    gvf = loop and scenario.guidance.mode is GuidanceMode.GVF
    worst_case = dist.model is DisturbanceModel.WORST_CASE
    run = to_parameters(RunConfig(dt=ctrl.dt, lockstep=speed == 0.0, seed=scenario.seed))
    dims = to_parameters(Dimensions(n=plant.n, m=plant.m, q=dist.q))
    world = to_parameters(WorldSource(scenario=scenario.path))
    sim_time = {'use_sim_time': True}
    clock = (topics.CLOCK,)

    def only(params: dict[str, Any], *names: str) -> dict[str, Any]:
        return {k: v for k, v in params.items() if k in names}

    controller = NodeSpec(
        'controller', 'rrtq_controller.controller_node', 'ControllerNode',
        {**sim_time, **dims, **only(run, 'lockstep', 'seed'), **to_parameters(ctrl),
         **(to_parameters(scenario.lpc, exclude=('force_limit',)) if vf_lpc else {})},
        subscribes=clock + (topics.ODOM,) + ((topics.PLANNER_STATS,) if loop else ())
        + ((topics.DISTURBANCE,) if ctrl.reads_disturbance else ())
        + ((topics.GUIDANCE_REFERENCE,) if vf_lpc else ()),
        publishes=(topics.CMD_FORCE, topics.CONTROLLER_STATE))
    disturbance = NodeSpec(
        'disturbance_injector', 'rrtq_sim.disturbance_node', 'DisturbanceNode',
        {**sim_time, **dims, **only(run, 'seed'), **to_parameters(dist),
         **(to_parameters(worst_case_game(scenario)) if worst_case else {})},
        subscribes=clock + (topics.ODOM_TRUTH,)
        + ((topics.CONTROLLER_STATE,) if worst_case else ()),
        publishes=(topics.DISTURBANCE,))
    scan = scenario.perception.source is PerceptionSource.SCAN
    physics = plant.model is PlantModel.MUJOCO
    spawner = NodeSpec('obstacle_spawner', 'rrtq_sim.spawner_node', 'SpawnerNode',
                       {**sim_time, **world, **(only(run, 'dt', 'seed') if scan else {}),
                        **(to_parameters(ScanWorld(plant.model, plant.mjcf))
                           if scan and physics else {})},
                       subscribes=clock + (topics.ODOM_TRUTH,),
                       publishes=((topics.SCAN,) if scan else (topics.PERCEPTION_STATUS,))
                       + (topics.REFEREE_STATUS,))
    published = tuple(t for t in STEP_TOPICS if loop or t not in LOOP_TOPICS) + (
        (topics.GUIDANCE_REFERENCE,) if gvf else ()) + ((topics.SCAN,) if scan else ())
    recorder = NodeSpec('recorder', 'rrtq_bringup.recorder_node', 'RecorderNode',
                        to_parameters(RecorderConfig(output=output, scenario=scenario.path)),
                        subscribes=published)
    supervisor = NodeSpec('supervisor', 'rrtq_bringup.supervisor', 'SupervisorNode', {},
                          subscribes=(topics.ODOM_TRUTH, topics.CMD_FORCE,
                                      topics.CONTROLLER_STATE)
                          + ((topics.PLANNER_STATS,) if loop else ()))
    # For people only (/tf and markers): outside the lock-step chain, nothing reads it. It
    # draws the robot where its odometry puts it (/tf map -> base_link, as a robot's
    # localisation would), not the truth.
    viz = NodeSpec('viz', 'rrtq_bringup.viz_node', 'VizNode',
                   to_parameters(VizConfig(robot_radius=scenario.robot_radius,
                                           perception_radius=scenario.perception_radius)),
                   subscribes=(topics.ODOM, topics.CONTROLLER_STATE))
    others = [recorder, supervisor, controller, disturbance, spawner, viz]
    if live_port is not None:
        # A reader of every topic, gating nothing: the run never waits for the viewer.
        others.append(NodeSpec('live', 'rrtq_bringup.live_node', 'LiveNode',
                               to_parameters(LiveConfig(port=live_port))))
    if scan:
        p = scenario.perception
        assert p.range_max is not None
        mapper = MapperConfig(beams=p.beams, range_max=p.range_max, noise_std=p.noise_std,
                              rate=p.rate)
        others.append(NodeSpec(
            'obstacle_mapper', 'rrtq_planner.obstacle_mapper_node', 'ObstacleMapperNode',
            {**sim_time, **only(run, 'dt', 'lockstep'), **to_parameters(mapper)},
            subscribes=clock + (topics.ODOM, topics.SCAN),
            publishes=(topics.PERCEPTION_STATUS,)))
    if loop:
        others.append(NodeSpec(
            'planner', 'rrtq_planner.planner_node', 'PlannerNode',
            {**sim_time, **run, **to_parameters(scenario.planner),
             **(to_parameters(scenario.guidance, exclude=('dt',)) if gvf else {})},
            subscribes=clock + (topics.ODOM, topics.SAFETY_STATUS),
            publishes=(topics.PLANNER_STATS,) + ((topics.GUIDANCE_REFERENCE,) if gvf else ())))
        others.append(NodeSpec(
            'safety', 'rrtq_planner.safety_node', 'SafetyNode',
            # No scenario file: the scenario's obstacles are the truth the robot must not
            # know; its bounds and robot radius come in the safety settings.
            {**sim_time, **dims, **only(run, 'dt', 'lockstep'),
             **to_parameters(scenario.safety), **to_parameters(scenario.margins)},
            subscribes=clock + (topics.ODOM, topics.PERCEPTION_STATUS,
                                topics.CONTROLLER_STATE),
            publishes=(topics.SAFETY_STATUS,)))
    # The first step waits until every reader of the per-step topics is connected,
    # so that no node (and not the recorder) misses step 0: the simulator counts the
    # readers its own writers have matched, every other writer's node announces when its
    # writers have matched theirs (rrtq_common.readiness, rclpy-side).
    readers = {topic: sum(topic in s.subscribes for s in others) + (topic in SIMULATOR_READS)
               for topic in published}
    wait_for = tuple(f'{topic}:{count}' for topic, count in readers.items())
    announcing = []
    for i, spec in enumerate(others):
        expected = [f'{topic}:{readers[topic]}' for topic in spec.publishes if topic in readers]
        if expected:
            others[i] = dataclasses.replace(
                spec, params={**spec.params, READY_PARAMETER: expected})
            announcing.append(spec.name)
    simulator = SimulatorConfig(start=(float(scenario.start[0]), float(scenario.start[1])),
                                speed=speed, duration=scenario.duration,
                                acks=('cmd_force', 'controller_state', 'disturbance'),
                                wait_for=wait_for, ready_from=tuple(announcing))
    # The physics plant also builds its obstacles from the scenario file; the linear plants
    # need only their matrices.
    plant_params = (to_parameters(plant, exclude=('stiffness',) + (('damping',) if plant.mjcf
                                                                     else ()))
                    if physics else to_parameters(plant, exclude=(
                        'model', 'mass', 'stiffness', 'damping', 'friction', 'mjcf')))
    simulator_spec = NodeSpec(
        'simulator', 'rrtq_sim.simulator_node', 'SimulatorNode',
        {**only(dims, 'n'), **only(run, 'dt', 'seed'), **plant_params,
         **(world if physics else {}), **to_parameters(scenario.odometry_noise),
         'F': to_parameters(dist)['F'], **to_parameters(simulator)},
        subscribes=SIMULATOR_READS)
    return [simulator_spec, *others]
