"""The VF-LPC keys of a scenario: ``planner.guidance``, ``controller.model``, ``controller.vf_lpc``.

``planner.guidance`` is read into :class:`rrtq_planner.guidance.GuidanceConfig` (its fields
are the keys; ``dt`` is the controller's). ``controller.model`` names a model file written
by ``rrtq identify`` (relative to the scenario file); it is loaded here, so a missing or
bad file, or one identified for another plant size or step, is an error before anything
starts. ``controller.vf_lpc`` is :class:`rrtq_controller.vf_lpc.LPCConfig` without
``force_limit`` (the actuator's, ``controller.force_limit``).

The keys are accepted with any controller variant (so that one file serves a
``--set controller.variant=nominal,vf_lpc`` sweep); only ``vf_lpc`` uses the model, and it
needs ``planner.guidance.mode: gvf``.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

from rrtq_common.yaml_reader import Reader, field_default
from rrtq_controller.config import ControllerConfig, Variant
from rrtq_controller.vf_lpc import KoopmanModel, LPCConfig
from rrtq_planner.guidance import GuidanceConfig, GuidanceMode
from rrtq_sim.plant import PlantConfig

__all__ = ['read_guidance', 'read_vf_lpc']

_GUIDANCE_KEYS = tuple(f.name for f in dataclasses.fields(GuidanceConfig) if f.name != 'dt')
_LPC_KEYS = tuple(f.name for f in dataclasses.fields(LPCConfig) if f.name != 'force_limit')


def read_guidance(r: Reader, raw: Any, dt: float) -> GuidanceConfig:
    """``planner.guidance``: waypoints (default) or the guiding vector field."""
    key = 'planner.guidance'
    data = r.mapping({} if raw is None else raw, key, _GUIDANCE_KEYS)
    mode = r.choice(data.get('mode', field_default(GuidanceConfig, 'mode')), f'{key}.mode',
                    GuidanceMode)
    values = {name: r.setting(data, name, GuidanceConfig, key)
              for name in _GUIDANCE_KEYS if name != 'mode'}
    if values['repulsive_offset'] >= values['reactive_width']:
        raise r.error(f'{key}.repulsive_offset',
                      f'must be below reactive_width ({values["reactive_width"]:g} m), '
                      f'got {values["repulsive_offset"]:g}')
    return GuidanceConfig(mode=mode, dt=dt, **values)


def read_vf_lpc(r: Reader, raw: Any, controller: ControllerConfig, plant: PlantConfig,
                guidance: GuidanceConfig, base: str) -> tuple[ControllerConfig, LPCConfig]:
    """``controller.model`` and ``controller.vf_lpc``; the model file loaded and checked.

    Returns the controller's settings with ``model`` made absolute, and the LPC's.
    """
    data = raw if isinstance(raw, dict) else {}
    lpc_raw = r.mapping(data.get('vf_lpc') or {}, 'controller.vf_lpc', _LPC_KEYS)
    values: dict[str, Any] = {}
    for name in _LPC_KEYS:
        if name == 'compensate':
            values[name] = r.boolean(lpc_raw.get(name, True), 'controller.vf_lpc.compensate')
        else:
            values[name] = r.setting(lpc_raw, name, LPCConfig, 'controller.vf_lpc')
    vf_lpc = controller.variant is Variant.VF_LPC
    limit = controller.force_limit
    if vf_lpc and not math.isfinite(limit):
        raise r.error('controller.force_limit', 'the vf_lpc variant needs a finite actuator '
                      'limit (its solver bounds every input by it)')
    lpc = LPCConfig(force_limit=limit if math.isfinite(limit) else
                    field_default(LPCConfig, 'force_limit'), **values)
    model = data.get('model')
    if model is None:
        if vf_lpc:
            raise r.error('controller.model', 'required for the vf_lpc variant (a model file '
                          'written by rrtq identify)')
        return controller, lpc
    file = os.path.normpath(os.path.join(base, r.string(model, 'controller.model')))
    if not os.path.isfile(file):
        raise r.error('controller.model', f'no such file: {file}')
    try:
        loaded = KoopmanModel.load(file)
    except ValueError as exc:
        raise r.error('controller.model', str(exc)) from None
    if (loaded.n, loaded.m) != (plant.n, plant.m):
        raise r.error('controller.model', f'{file}: a model of {loaded.n} states and '
                      f'{loaded.m} inputs, the plant has {plant.n} and {plant.m}')
    if not math.isclose(loaded.dt, controller.dt, rel_tol=1e-9):
        raise r.error('controller.model', f'{file}: identified at dt = {loaded.dt:g} s, the '
                      f'controller steps every {controller.dt:g} s')
    if vf_lpc and guidance.mode is not GuidanceMode.GVF:
        raise r.error('planner.guidance.mode', 'the vf_lpc controller tracks the guidance '
                      'reference: set planner.guidance.mode: gvf')
    return dataclasses.replace(controller, model=file), lpc
