"""The scenario: a world and the settings of every core, composed, not copied.

docs/design.md's "Scenario contract" (and ``docs/scenarios.md``): the world keys are
:class:`rrtq_common.world.World`'s; each section is the settings dataclass of the core
it configures — ``plant:`` :class:`rrtq_sim.plant.PlantConfig` (and ``plant.odometry_noise``
:class:`rrtq_sim.odometry.OdometryNoiseConfig`), ``disturbance:``
:class:`rrtq_sim.disturbance.DisturbanceConfig`, ``controller:``
:class:`rrtq_controller.config.ControllerConfig`, ``planner:``
:class:`rrtq_planner.session.PlannerConfig` (and two settings it hands on: the safety
node's ``growth_threshold``, the referee's ``goal_tolerance``); ``safety:``
:class:`rrtq_planner.margins.build.MarginConfig`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rrtq_bringup.mission import MissionConfig
from rrtq_common.settings import like, setting
from rrtq_common.world import World
from rrtq_controller.config import ControllerConfig
from rrtq_planner.margins.build import MarginConfig
from rrtq_controller.vf_lpc import LPCConfig
from rrtq_planner.guidance import GuidanceConfig
from rrtq_planner.safety import SafetyConfig
from rrtq_planner.session import PlannerConfig
from rrtq_sim.disturbance import DisturbanceConfig
from rrtq_sim.odometry import OdometryNoiseConfig
from rrtq_sim.plant import PlantConfig

__all__ = ['Scenario']


@dataclass(frozen=True, eq=False, kw_only=True)
class Scenario(World):
    """A validated scenario: its world (bounds, start, goal, obstacles...) and its settings.

    Attributes
    ----------
    path : str
        The file it came from.
    name : str
        Run name (default: the file stem).
    seed : int
        Seed of every random generator in the run.
    duration : float
        Simulated time before the run is declared failed, s.
    plant, disturbance, controller, planner, safety
        The settings of the simulator's plant, the disturbance injector, the controller,
        the planner node and the safety node.
    margins : MarginConfig
        The ``safety:`` section: the safety node's margin policy.
    goal_tolerance : float
        m; the referee's distance to the goal that counts as reached.
    guidance : GuidanceConfig
        ``planner.guidance``: what the planner hands the controller (waypoints, or the
        guiding vector field's reference).
    lpc : LPCConfig
        ``controller.vf_lpc``: the vf_lpc controller's solver and compensation.
    odometry_noise : OdometryNoiseConfig
        ``plant.odometry_noise``: what the simulator's /odom adds to the true state.
    """

    path: str
    name: str
    seed: int = setting(0, low=0, doc='seed of every random generator in the run')
    duration: float = setting(300.0, unit='s', low=0.0, low_open=True,
                              doc='simulated time before the run is declared failed')
    plant: PlantConfig
    disturbance: DisturbanceConfig
    controller: ControllerConfig
    planner: PlannerConfig
    safety: SafetyConfig
    margins: MarginConfig = MarginConfig()
    goal_tolerance: float = like(MissionConfig, 'goal_tolerance')
    guidance: GuidanceConfig = field(default_factory=GuidanceConfig)
    lpc: LPCConfig = field(default_factory=LPCConfig)
    odometry_noise: OdometryNoiseConfig = field(default_factory=OdometryNoiseConfig)
