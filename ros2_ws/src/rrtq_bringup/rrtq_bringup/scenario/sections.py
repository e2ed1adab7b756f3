"""The sections of a scenario file, each read into the settings dataclass of its core.

Defaults and ranges come from the dataclasses (:meth:`rrtq_common.yaml_reader.Reader.setting`);
what is checked here is what a dataclass cannot know alone: which keys a section allows,
shapes that depend on the plant, settings required by a variant or a model.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from rrtq_bringup.mission import MissionConfig
from rrtq_common.world import World
from rrtq_common.yaml_reader import Reader, field_default, frozen
from rrtq_controller.config import ControllerConfig, Variant
from rrtq_planner.margins.build import MarginConfig
from rrtq_planner.margins.calibration import read_calibration
from rrtq_planner.margins.learned_data import ModelFrame
from rrtq_planner.margins.policy import MarginMode
from rrtq_planner.safety import SafetyConfig
from rrtq_planner.session import PlannerConfig
from rrtq_sim.disturbance import DisturbanceConfig, DisturbanceModel
from rrtq_sim.field import field_input_matrix
from rrtq_sim.odometry import OdometryNoiseConfig
from rrtq_sim.plant import PlantConfig, PlantModel, rover_matrices

__all__ = ['read_plant', 'read_odometry_noise', 'read_disturbance', 'read_controller',
           'read_planner', 'read_safety']

_SENSING_KEYS = ('actuation_delay', 'odometry_noise')
_ROVER_KEYS = ('model', 'mass', 'stiffness', 'damping', 'spring_anchor', 'force_limit',
               *_SENSING_KEYS)
_LTI_KEYS = ('model', 'A', 'B', 'spring_anchor', 'force_limit', *_SENSING_KEYS)
_MUJOCO_KEYS = ('model', 'mass', 'damping', 'friction', 'mjcf', 'force_limit', *_SENSING_KEYS)
_MJCF_OWN = ('mass', 'damping', 'friction')
"""What a user's MJCF file defines itself: not keys beside ``plant.mjcf``."""
# plant.odometry_noise key -> OdometryNoiseConfig field
_NOISE_KEYS = {'position': 'position_std', 'velocity': 'velocity_std'}
_DIST_KEYS = ('model', 'F', 'amplitude', 'frequency', 'gamma', 'bumps')
_BUMP_KEYS = ('center', 'radius', 'value')
_SAFETY_KEYS = ('margin', 'confidence', 'window', 'initial_margin', 'calibration',
                'prior_bound', 'conformal')
_CTRL_KEYS = (
    'variant', 'horizon', 'dt', 'M', 'R', 'P_T', 'alpha_c', 'alpha_a', 'alpha_d', 'gamma', 'rho',
    'forces', 'critic_law', 'actor_law', 'initial_gain', 'probing_std', 'probing_decay',
    'probing_line_fraction', 'force_limit', 'measured_disturbance', 'observer',
    'disturbance_estimate', 'rollout_test', 'push_feedforward', 'push_feedforward_law',
    'push_filter_time', 'integral_action', 'friction_compensation', 'model',
    'vf_lpc',
)  # fmt: skip
# planner key -> the settings dataclass it belongs to
_PLANNER_KEYS: dict[str, type] = {
    'steer_distance': PlannerConfig, 'epsilon': PlannerConfig,
    'iterations_per_step': PlannerConfig, 'max_nodes': PlannerConfig,
    'cycle_budget_ms': PlannerConfig, 'tree_period_s': PlannerConfig, 'stall_time': PlannerConfig,
    'goal_tolerance': MissionConfig, 'growth_threshold': SafetyConfig,
}
_UNBOUNDED = frozenset({'stall_time'})
"""Planner keys that may be .inf (never)."""


def _choice(r: Reader, data: dict[str, Any], name: str, cls: type, section: str) -> Any:
    enum_type = type(field_default(cls, name))
    return r.choice(data.get(name, field_default(cls, name)), f'{section}.{name}', enum_type)


def _read_mujoco(r: Reader, data: dict[str, Any], limit: float, base: str) -> PlantConfig:
    """``plant: {model: mujoco}``: the shipped base (mass, damping, friction) or ``mjcf``."""
    key = 'plant'
    delay = r.setting(data, 'actuation_delay', PlantConfig, key)
    if data.get('mjcf') is None:
        mass, damping, friction = (r.setting(data, name, PlantConfig, key)
                                   for name in _MJCF_OWN)
        a, b = rover_matrices(mass, 0.0, damping)
        return PlantConfig(model=PlantModel.MUJOCO, A=frozen(a), B=frozen(b), mass=mass,
                           stiffness=0.0, damping=damping, friction=friction,
                           force_limit=limit, actuation_delay=delay)
    for name in _MJCF_OWN:
        if name in data:
            raise r.error(f'plant.{name}', 'not with plant.mjcf: the MJCF file defines it')
    file = os.path.normpath(os.path.join(base, os.path.expanduser(
        r.string(data['mjcf'], 'plant.mjcf'))))
    # MuJoCo loads only for a scenario that uses it (0.3 s of import on every other run).
    from rrtq_sim.mujoco_model import BASE_BODY, MjcfError, build_model
    try:
        model = build_model([], 0.005, mjcf=file)
    except MjcfError as exc:
        raise r.error('plant.mjcf', str(exc)) from None
    mass = float(model.body_subtreemass[model.body(BASE_BODY).id])
    if not mass > 0.0:
        raise r.error('plant.mjcf', f'{file}: body {BASE_BODY!r} has no mass')
    a, b = rover_matrices(mass, 0.0, 0.0)
    return PlantConfig(model=PlantModel.MUJOCO, A=frozen(a), B=frozen(b), mass=mass,
                       stiffness=0.0, damping=np.nan, mjcf=file, force_limit=limit,
                       actuation_delay=delay)


def read_plant(r: Reader, raw: Any, base: str = '') -> PlantConfig:
    """``plant:``: the rover (mass, stiffness, damping), an LTI plant (A, B) or mujoco.

    ``base``: the directory a relative ``plant.mjcf`` is read from (the scenario's).
    """
    key = 'plant'
    data = r.mapping({} if raw is None else raw, key, None)
    model = _choice(r, data, 'model', PlantConfig, key)
    data = r.mapping(data, key, {PlantModel.ROVER: _ROVER_KEYS, PlantModel.LTI: _LTI_KEYS,
                                 PlantModel.MUJOCO: _MUJOCO_KEYS}[model])
    anchor = _choice(r, data, 'spring_anchor', PlantConfig, key)
    limit = r.setting(data, 'force_limit', PlantConfig, key, allow_inf=True)
    if model is PlantModel.MUJOCO:
        return _read_mujoco(r, data, limit, base)
    if model is PlantModel.ROVER:
        mass, stiffness, damping = (r.setting(data, name, PlantConfig, key)
                                    for name in ('mass', 'stiffness', 'damping'))
        a, b = rover_matrices(mass, stiffness, damping)
    else:
        for name in ('A', 'B'):
            if name not in data:
                raise r.error(f'plant.{name}', 'required for model lti')
        a = r.matrix(data['A'], 'plant.A', (None, None))
        if a.shape[0] != a.shape[1] or a.shape[0] < 2:
            raise r.error(
                'plant.A', f'must be n x n with n >= 2 (states 0, 1: position), got {a.shape}'
            )
        b = r.matrix(data['B'], 'plant.B', (a.shape[0], None))
        mass = stiffness = damping = np.nan
    return PlantConfig(model=model, A=frozen(a), B=frozen(b), mass=mass, stiffness=stiffness,
                       damping=damping, spring_anchor=anchor, force_limit=limit,
                       actuation_delay=r.setting(data, 'actuation_delay', PlantConfig, key))


def read_odometry_noise(r: Reader, raw: Any) -> OdometryNoiseConfig:
    """``plant.odometry_noise: {position: m, velocity: m/s}`` (``raw``: the plant section)."""
    plant = raw if isinstance(raw, Mapping) else {}
    key = 'plant.odometry_noise'
    data = r.mapping({} if plant.get('odometry_noise') is None else plant['odometry_noise'],
                     key, tuple(_NOISE_KEYS))
    return OdometryNoiseConfig(**{name: r.setting(data, name, OdometryNoiseConfig, key,
                                                  key=file_key)
                                  for file_key, name in _NOISE_KEYS.items()})


def read_disturbance(r: Reader, raw: Any, n: int, needs_f: bool) -> DisturbanceConfig:
    """``disturbance:``; F defaults to the rover's column when n = 4."""
    key = 'disturbance'
    data = r.mapping({} if raw is None else raw, key, _DIST_KEYS)
    model = _choice(r, data, 'model', DisturbanceConfig, key)
    if model is DisturbanceModel.FIELD:
        return _read_field(r, data, n)
    if 'bumps' in data:
        raise r.error('disturbance.bumps', f'only for model field, not {model}')
    if 'F' in data:
        f = r.matrix(data['F'], 'disturbance.F', (n, None))
    elif n == 4:
        f = field_default(DisturbanceConfig, 'F')
    elif model is DisturbanceModel.NONE and not needs_f:
        f = np.zeros((n, 1))
    else:
        raise r.error('disturbance.F', f'required when the plant has n = {n} != 4 states')
    signed = model in (DisturbanceModel.CONSTANT, DisturbanceModel.SINUSOID)
    amplitude = r.number(data.get('amplitude', field_default(DisturbanceConfig, 'amplitude')),
                         'disturbance.amplitude', nonnegative=not signed)
    gamma = r.setting(data, 'gamma', DisturbanceConfig, key)
    if model is DisturbanceModel.WORST_CASE and gamma is None:
        raise r.error('disturbance.gamma', 'required for model worst_case')
    return DisturbanceConfig(model=model, F=frozen(f), amplitude=amplitude,
                             frequency=r.setting(data, 'frequency', DisturbanceConfig, key),
                             gamma=gamma)


def _read_field(r: Reader, data: dict[str, Any], n: int) -> DisturbanceConfig:
    """``disturbance: {model: field, bumps: [...]}``: F is the field's E = [0; I2]."""
    for name in ('F', 'amplitude', 'frequency', 'gamma'):
        if name in data:
            raise r.error(f'disturbance.{name}', 'not for model field (the field enters '
                          'the velocity rows: F = [0; I2])')
    if n < 4:
        raise r.error('disturbance.model', f'field acts on state components 2, 3 (the '
                      f'velocities): needs n >= 4, the plant has n = {n}')
    raw = data.get('bumps')
    key = 'disturbance.bumps'
    if not isinstance(raw, list) or not raw:
        raise r.error(key, 'expected a non-empty list of {center: [x, y], radius: r, '
                      'value: [ax, ay]}')
    bumps = []
    for i, entry in enumerate(raw):
        k = f'{key}[{i}]'
        bump = r.mapping(entry, k, _BUMP_KEYS)
        for name in _BUMP_KEYS:
            if name not in bump:
                raise r.error(f'{k}.{name}', 'required')
        center = r.point(bump['center'], f'{k}.center')
        radius = r.number(bump['radius'], f'{k}.radius', positive=True)
        value = r.point(bump['value'], f'{k}.value')
        bumps.append((float(center[0]), float(center[1]), radius,
                      float(value[0]), float(value[1])))
    return DisturbanceConfig(model=DisturbanceModel.FIELD, F=frozen(field_input_matrix(n)),
                             bumps=tuple(bumps))


def read_safety(r: Reader, raw: Any, base: str, plant: PlantConfig) -> MarginConfig:
    """``safety:``: the margin policy; a calibration file is read now (path from ``base``)."""
    key = 'safety'
    data = r.mapping({} if raw is None else raw, key, _SAFETY_KEYS)
    mode = _choice(r, data, 'margin', MarginConfig, key)
    calibration = None
    if data.get('calibration') is not None:
        if mode is MarginMode.RUNNING_MAX:
            raise r.error('safety.calibration', 'only for margin: conformal or learned_bound, '
                          f'not {mode}')
        file = r.string(data['calibration'], 'safety.calibration')
        path = os.path.abspath(os.path.join(base, os.path.expanduser(file)))
        try:
            read_calibration(path)
        except ValueError as exc:
            raise r.error('safety.calibration', str(exc)) from None
        calibration = path
    values = {name: r.setting(data, name, MarginConfig, key)
              for name in ('confidence', 'window', 'initial_margin', 'prior_bound')}
    values['conformal'] = r.boolean(data.get('conformal', field_default(MarginConfig,
                                                                        'conformal')),
                                    'safety.conformal')
    return MarginConfig(margin=mode, calibration=calibration,
                        frame=ModelFrame(plant.spring_anchor.value), **values)


def _forces(r: Reader, raw: Any, key: str) -> tuple[tuple[float, float, float], ...]:
    if not isinstance(raw, list) or not raw:
        raise r.error(key, 'expected a non-empty list of [t, fx, fy]')
    out: list[tuple[float, float, float]] = []
    for i, row in enumerate(raw):
        k = f'{key}[{i}]'
        if not isinstance(row, list) or len(row) != 3:
            raise r.error(k, f'expected [t, fx, fy], got {row!r}')
        t = r.number(row[0], f'{k}[0]', nonnegative=True)
        if out and not t > out[-1][0]:
            raise r.error(k, f'times must be strictly increasing ({t} after {out[-1][0]})')
        out.append((t, r.number(row[1], f'{k}[1]'), r.number(row[2], f'{k}[2]')))
    return tuple(out)


def read_controller(r: Reader, raw: Any, plant: PlantConfig, world: World) -> ControllerConfig:
    """``controller:``; the open-loop variant's target is the scenario's goal."""
    key = 'controller'
    n, m = plant.n, plant.m
    data = r.mapping({} if raw is None else raw, key, _CTRL_KEYS)
    variant = _choice(r, data, 'variant', ControllerConfig, key)
    horizon = r.setting(data, 'horizon', ControllerConfig, key)
    dt = r.setting(data, 'dt', ControllerConfig, key)
    if dt > horizon:
        raise r.error('controller.dt', f'dt = {dt} s exceeds the horizon {horizon} s')
    weights = {
        name: frozen(r.weight(data.get(name, field_default(ControllerConfig, name)),
                              f'controller.{name}', size, definite=definite))
        for name, size, definite in (('M', n, False), ('R', m, True), ('P_T', n, False))
    }
    gamma = r.setting(data, 'gamma', ControllerConfig, key)
    if variant is Variant.ROBUST and gamma is None:
        raise r.error('controller.gamma', 'required for the robust variant')
    forces: tuple[tuple[float, float, float], ...] = ()
    if variant is Variant.OPEN_LOOP:
        if 'forces' not in data:
            raise r.error('controller.forces', 'required for the open_loop variant')
        if m != 2:
            raise r.error(
                'controller.forces', f'[t, fx, fy] needs a plant with 2 inputs, this one has {m}'
            )
        forces = _forces(r, data['forces'], 'controller.forces')
    elif 'forces' in data:
        raise r.error('controller.forces', f'only for the open_loop variant, not {variant}')
    gain = None
    if data.get('initial_gain') is not None:
        matrix = r.matrix(data['initial_gain'], 'controller.initial_gain', (m, n))
        gain = tuple(tuple(float(v) for v in row) for row in matrix)
    numbers = {name: r.setting(data, name, ControllerConfig, key)
               for name in ('alpha_c', 'alpha_a', 'alpha_d', 'rho', 'probing_std',
                            'probing_decay', 'push_filter_time')}
    numbers['probing_line_fraction'] = r.setting(data, 'probing_line_fraction', ControllerConfig,
                                                 key, allow_inf=True)
    # the actuator's limit is the user's specification; by default the plant's
    limit = (plant.force_limit if data.get('force_limit') is None
             else r.setting(data, 'force_limit', ControllerConfig, key, allow_inf=True))
    return ControllerConfig(
        variant=variant, horizon=horizon, dt=dt, gamma=gamma, forces=forces,
        force_limit=limit,
        goal=(float(world.goal[0]), float(world.goal[1])),
        critic_law=_choice(r, data, 'critic_law', ControllerConfig, key),
        actor_law=_choice(r, data, 'actor_law', ControllerConfig, key),
        push_feedforward_law=_choice(r, data, 'push_feedforward_law', ControllerConfig, key),
        initial_gain=gain,
        **{name: r.boolean(data.get(name, field_default(ControllerConfig, name)),
                           f'controller.{name}')
           for name in ('measured_disturbance', 'observer', 'disturbance_estimate',
                        'rollout_test', 'push_feedforward', 'integral_action',
                        'friction_compensation')},
        **weights, **numbers)


def read_planner(r: Reader, raw: Any,
                 world: World) -> tuple[PlannerConfig, SafetyConfig, float]:
    """``planner:``: the planner node's settings, and two it hands on.

    Those are the safety node's growth threshold and the referee's goal tolerance.
    """
    key = 'planner'
    data = r.mapping({} if raw is None else raw, key, (*_PLANNER_KEYS, 'guidance'))
    values = {name: r.setting(data, name, cls, key, allow_inf=name in _UNBOUNDED)
              for name, cls in _PLANNER_KEYS.items()}
    (x0, x1), (y0, y1) = world.bounds
    planner = PlannerConfig(bounds=(x0, x1, y0, y1), **{
        name: values[name] for name, cls in _PLANNER_KEYS.items() if cls is PlannerConfig})
    safety = SafetyConfig(robot_radius=world.robot_radius, bounds=(x0, x1, y0, y1),
                          growth_threshold=values['growth_threshold'])
    return planner, safety, values['goal_tolerance']

