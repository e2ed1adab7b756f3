"""Reading a scenario file: the whole schema, then the game check; the builders of its cores.

Every problem is a :class:`rrtq_common.yaml_reader.ScenarioError` naming the file and the
dotted key, raised before anything starts (exit code 2).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from rrtq_bringup.scenario.schema import Scenario
from rrtq_bringup.scenario.sections import (read_controller, read_disturbance,
                                            read_odometry_noise, read_planner, read_plant,
                                            read_safety)
from rrtq_bringup.scenario.vf_lpc import read_guidance, read_vf_lpc
from rrtq_common.scan import PerceptionSource, period_steps
from rrtq_common.world import World
from rrtq_common.world_yaml import read_world
from rrtq_common.yaml_reader import Reader, ScenarioError, read_yaml
from rrtq_controller.config import ControllerConfig, Variant
from rrtq_sim.disturbance import (DisturbanceGenerator, DisturbanceModel, WorstCaseGame,
                                  make_generator)
from rrtq_sim.plant import Plant, PlantConfig, PlantModel
from rrtq_sim.riccati import RiccatiEscape, RiccatiSolution, game_gamma_bound, solve_riccati
from rrtq_sim.simulation import delay_steps

__all__ = ['parse_scenario', 'load_scenario', 'build_plant', 'worst_case_game',
           'game_riccati', 'build_disturbance']

_TOP_KEYS = (
    'name', 'seed', 'bounds', 'start', 'goal', 'duration', 'perception_radius',
    'robot_radius', 'appear_clearance', 'plant', 'disturbance', 'controller', 'planner',
    'obstacles', 'safety', 'perception',
)  # fmt: skip


def _check_game(r: Reader, key: str, plant: PlantConfig, ctrl: ControllerConfig,
                f: np.ndarray, gamma: float) -> None:
    """Reject a gamma below the finite-horizon game bound: no saddle point exists."""
    try:
        solve_riccati(plant.A, plant.B, ctrl.M, ctrl.R, ctrl.P_T, ctrl.horizon, f, gamma)
    except RiccatiEscape as exc:
        # Coarse: the bound only has to tell the user roughly where to go.
        bound = game_gamma_bound(
            plant.A, plant.B, ctrl.M, ctrl.R, ctrl.P_T, ctrl.horizon, f, tol=0.02
        )
        raise r.error(
            key, f'gamma = {gamma} is below the game bound (about {bound:.3g}) ({exc})'
        ) from None


def parse_scenario(data: Any, path: str) -> Scenario:
    """Validate parsed YAML and build a :class:`Scenario`.

    Parameters
    ----------
    data : dict
        The parsed document.
    path : str
        The file it came from: named in errors, and the base for relative obstacle files.

    Raises
    ------
    ScenarioError
    """
    r = Reader(path)
    if not isinstance(data, Mapping):
        raise r.error('', f'the top level must be a mapping, got {type(data).__name__}')
    data = r.mapping(data, '', _TOP_KEYS)
    world = read_world(r, data, os.path.dirname(os.path.abspath(path)))
    stem = os.path.splitext(os.path.basename(path))[0] or 'scenario'
    name = r.string(data.get('name', stem), 'name')
    seed = data.get('seed', 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise r.error('seed', f'expected an integer >= 0, got {seed!r}')
    plant = read_plant(r, data.get('plant'), os.path.dirname(os.path.abspath(path)))
    odometry_noise = read_odometry_noise(r, data.get('plant'))
    ctrl_raw = data.get('controller')
    robust = isinstance(ctrl_raw, Mapping) and ctrl_raw.get('variant') == Variant.ROBUST
    disturbance = read_disturbance(r, data.get('disturbance'), plant.n, robust)
    if plant.model is PlantModel.MUJOCO and np.any(disturbance.F[:2]):
        raise r.error('disturbance.F', 'with plant.model mujoco the disturbance is a force '
                      '(mass x acceleration): F must be zero in its position rows')
    controller = read_controller(r, ctrl_raw, plant, world)
    try:
        delay_steps(plant.actuation_delay, controller.dt)
    except ValueError as exc:
        raise r.error('plant.actuation_delay', str(exc)) from None
    if world.perception.source is PerceptionSource.SCAN:
        try:
            period_steps(world.perception.rate, controller.dt)
        except ValueError as exc:
            raise r.error('perception.rate', str(exc)) from None
    planner, safety, goal_tolerance = read_planner(r, data.get('planner'), world)
    margins = read_safety(r, data.get('safety'), os.path.dirname(os.path.abspath(path)), plant)
    planner_raw = data.get('planner')
    guidance = read_guidance(r, planner_raw.get('guidance') if isinstance(planner_raw, Mapping)
                             else None, controller.dt)
    controller, lpc = read_vf_lpc(r, ctrl_raw, controller, plant, guidance,
                                  os.path.dirname(os.path.abspath(path)))
    if disturbance.model is DisturbanceModel.WORST_CASE:
        assert disturbance.gamma is not None
        _check_game(r, 'disturbance.gamma', plant, controller, disturbance.F, disturbance.gamma)
    if controller.variant is Variant.ROBUST:
        assert controller.gamma is not None
        _check_game(r, 'controller.gamma', plant, controller, disturbance.F, controller.gamma)
    world_fields = {f.name: getattr(world, f.name) for f in dataclasses.fields(World)}
    return Scenario(path=path, name=name, seed=seed,
                    duration=r.setting(data, 'duration', Scenario), plant=plant,
                    disturbance=disturbance, controller=controller, planner=planner,
                    safety=safety, margins=margins, goal_tolerance=goal_tolerance, guidance=guidance,
                    lpc=lpc, odometry_noise=odometry_noise, **world_fields)


def load_scenario(path: str | os.PathLike[str], seed: int | None = None) -> Scenario:
    """Read, validate and build a scenario file.

    Parameters
    ----------
    path : str or path-like
    seed : int, optional
        Overrides the file's seed (``rrtq run --seed``).

    Raises
    ------
    ScenarioError
        With key '' for an unreadable file, a YAML error or a non-mapping document.
    """
    file = os.fspath(path)
    scenario = parse_scenario(read_yaml(file), file)
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ScenarioError(
                file, 'seed', f'the seed override must be an integer >= 0, got {seed!r}'
            )
        scenario = dataclasses.replace(scenario, seed=seed)
    return scenario


def build_plant(scenario: Scenario) -> Plant:
    """The simulator's plant: true matrices, F, the controller's dt, the force limit."""
    p = scenario.plant
    return Plant(p.A, p.B, scenario.disturbance.F, scenario.controller.dt, p.force_limit)


def worst_case_game(scenario: Scenario) -> WorstCaseGame:
    """The game the worst-case disturbance plays: the true plant, the controller's cost."""
    p, c = scenario.plant, scenario.controller
    return WorstCaseGame(A=p.A, B=p.B, M=c.M, R=c.R, P_T=c.P_T, horizon=c.horizon)


def game_riccati(scenario: Scenario, gamma: float) -> RiccatiSolution:
    """Game Riccati solution over one leg (horizon T): controller weights, true plant."""
    return worst_case_game(scenario).riccati(scenario.disturbance.F, gamma)


def build_disturbance(scenario: Scenario, rng: np.random.Generator) -> DisturbanceGenerator:
    """The disturbance injector's generator (worst_case: the game at ``disturbance.gamma``)."""
    worst = scenario.disturbance.model is DisturbanceModel.WORST_CASE
    return make_generator(scenario.disturbance, rng, worst_case_game(scenario) if worst else None)
