"""The world keys of a scenario file: bounds, start, goal, perception, the obstacles.

:func:`read_world` is the part of the scenario schema that the nodes need (the spawner
and the safety node read the world from the scenario file the orchestrator validated,
with :func:`load_world`); the full schema (:mod:`rrtq_bringup.scenario`) reads the rest.
Otte files map as: flag 0 known, 1 unknown until sensed, -1 known but absent.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rrtq_common.geometry import point_polygon_distance, polygon_from_circle
from rrtq_common.otte import load_otte
from rrtq_common.scan import PerceptionConfig, PerceptionSource
from rrtq_common.settings import setting
from rrtq_common.world import ObstacleSpec, World
from rrtq_common.yaml_reader import Reader, ScenarioError, frozen, join, read_yaml

__all__ = ['WorldSource', 'read_world', 'load_world']

_TIMING_KEYS = ('appear_at', 'vanish_at', 'known')
# perception key -> PerceptionConfig field
_PERCEPTION_KEYS = {'source': 'source', 'beams': 'beams', 'range': 'range_max', 'rate': 'rate',
                    'noise': 'noise_std'}


@dataclass(frozen=True)
class WorldSource:
    """Where a node reads the world from: the run's scenario file."""

    scenario: str = setting('', doc='scenario YAML with the world (validated by the '
                            'orchestrator)')


def _timing(r: Reader, data: Mapping[str, Any], key: str) -> tuple[float, float, bool]:
    appear = r.number(data.get('appear_at', 0.0), join(key, 'appear_at'), nonnegative=True)
    vanish = r.number(
        data.get('vanish_at', math.inf), join(key, 'vanish_at'), nonnegative=True, allow_inf=True
    )
    # appear_at == vanish_at is allowed: an obstacle that never exists but may be
    # believed (known: true, vanish_at: 0 in the example of docs/design.md; Otte flag -1).
    if appear > vanish:
        raise r.error(
            join(key, 'vanish_at'), f'vanish_at = {vanish} is before appear_at = {appear}'
        )
    known = r.boolean(data.get('known', False), join(key, 'known'))
    return appear, vanish, known


def _obstacle_file(
    r: Reader, data: dict[str, Any], key: str, base_dir: str
) -> list[ObstacleSpec]:
    fmt = data.get('format', 'otte')
    if fmt != 'otte':
        raise r.error(join(key, 'format'), f"only 'otte' is supported, got {fmt!r}")
    rel = r.string(data['file'], join(key, 'file'))
    path = rel if os.path.isabs(rel) else os.path.join(base_dir, rel)
    discoverable = r.boolean(data.get('discoverable', False), join(key, 'discoverable'))
    if discoverable:
        for name in _TIMING_KEYS:
            if name in data:
                raise r.error(
                    join(key, name), "set by the file's flags when discoverable is true"
                )
    try:
        entries = load_otte(path)
    except OSError as exc:
        raise r.error(join(key, 'file'), f'cannot read {path}: {exc.strerror or exc}') from None
    except ValueError as exc:
        raise r.error(join(key, 'file'), str(exc)) from None
    stem = os.path.splitext(os.path.basename(path))[0]
    appear, vanish, known = _timing(r, data, key)
    specs = []
    for i, (poly, flag) in enumerate(entries):
        if discoverable:
            if flag is None:
                raise r.error(join(key, 'discoverable'), f'{path} has no flag lines')
            # Otte: 0 static and known; 1 unknown until sensed; -1 believed but absent.
            appear, vanish, known = 0.0, (0.0 if flag == -1 else math.inf), flag != 1
        specs.append(ObstacleSpec(f'{stem}_{i}', frozen(poly), appear, vanish, known))
    return specs


def _obstacles(r: Reader, raw: Any, base_dir: str) -> tuple[ObstacleSpec, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise r.error('obstacles', f'expected a list, got {type(raw).__name__}')
    specs: list[ObstacleSpec] = []
    seen: set[str] = set()
    for i, entry in enumerate(raw):
        key = f'obstacles[{i}]'
        if not isinstance(entry, Mapping):
            raise r.error(key, f'expected a mapping, got {type(entry).__name__}')
        shapes = [s for s in ('polygon', 'circle', 'file') if s in entry]
        if len(shapes) != 1:
            raise r.error(key, 'needs exactly one of polygon, circle, file')
        if shapes[0] == 'file':
            data = r.mapping(entry, key, ('file', 'format', 'discoverable') + _TIMING_KEYS)
            new = _obstacle_file(r, data, key, base_dir)
        else:
            data = r.mapping(entry, key, ('id', shapes[0]) + _TIMING_KEYS)
            if 'id' not in data:
                raise r.error(join(key, 'id'), 'required')
            ident = r.string(data['id'], join(key, 'id'))
            if shapes[0] == 'polygon':
                poly = r.polygon(data['polygon'], join(key, 'polygon'))
            else:
                ck = join(key, 'circle')
                circle = r.mapping(data['circle'], ck, ('center', 'radius'))
                for name in ('center', 'radius'):
                    if name not in circle:
                        raise r.error(join(ck, name), 'required')
                center = r.point(circle['center'], join(ck, 'center'))
                radius = r.number(circle['radius'], join(ck, 'radius'), positive=True)
                poly = polygon_from_circle(center, radius)
            new = [ObstacleSpec(ident, frozen(poly), *_timing(r, data, key))]
        for spec in new:
            if spec.id in seen:
                where = join(key, 'file' if shapes[0] == 'file' else 'id')
                raise r.error(where, f'duplicate id {spec.id!r}')
            seen.add(spec.id)
        specs.extend(new)
    return tuple(specs)


def _bounds(r: Reader, raw: Any) -> tuple[tuple[float, float], tuple[float, float]]:
    data = r.mapping(raw, 'bounds', ('x', 'y'))
    out = []
    for axis in ('x', 'y'):
        key = f'bounds.{axis}'
        if axis not in data:
            raise r.error(key, 'required')
        lo, hi = r.point(data[axis], key)
        if not lo < hi:
            raise r.error(key, f'expected [min, max] with min < max, got [{lo}, {hi}]')
        out.append((float(lo), float(hi)))
    return out[0], out[1]


def _perception(r: Reader, raw: Any, radius: float) -> PerceptionConfig:
    """``perception: {source, beams, range, rate, noise}``; ``range`` defaults to ``radius``."""
    key = 'perception'
    data = r.mapping({} if raw is None else raw, key, tuple(_PERCEPTION_KEYS))
    default = PerceptionConfig()
    source = r.choice(data.get('source', default.source), f'{key}.source', PerceptionSource)
    values = {name: r.setting(data, name, PerceptionConfig, key, key=file_key)
              for file_key, name in _PERCEPTION_KEYS.items() if file_key != 'source'}
    if values['range_max'] is None:
        values['range_max'] = radius
    return PerceptionConfig(source=source, **values)


def read_world(r: Reader, data: Mapping[str, Any], base_dir: str) -> World:
    """The world keys of a parsed scenario (other keys are not looked at).

    Raises
    ------
    ScenarioError
        Naming the key: a missing or malformed one, a start or goal outside the bounds
        or inside an obstacle.
    """
    for name in ('bounds', 'start', 'goal'):
        if name not in data:
            raise r.error(name, 'required')
    bounds = _bounds(r, data['bounds'])
    start = r.point(data['start'], 'start')
    goal = r.point(data['goal'], 'goal')
    radii = {name: r.setting(data, name, World)
             for name in ('perception_radius', 'robot_radius', 'appear_clearance')}
    obstacles = _obstacles(r, data.get('obstacles'), base_dir)
    perception = _perception(r, data.get('perception'), radii['perception_radius'])
    robot_radius = radii['robot_radius']
    for key, p in (('start', start), ('goal', goal)):
        (x0, x1), (y0, y1) = bounds
        if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            raise r.error(key, f'{p.tolist()} is outside the bounds x {[x0, x1]}, y {[y0, y1]}')
    for spec in obstacles:
        dist = float(point_polygon_distance(start, spec.polygon))
        blocked = dist <= 0.0 or dist < robot_radius
        if blocked and spec.exists(0.0):
            raise r.error('start', f'{start.tolist()} is inside obstacle {spec.id!r} at t = 0')
        dist = float(point_polygon_distance(goal, spec.polygon))
        if (dist <= 0.0 or dist < robot_radius) and spec.ever_exists:
            raise r.error('goal', f'{goal.tolist()} is inside obstacle {spec.id!r}')
    return World(bounds=bounds, start=frozen(start), goal=frozen(goal), obstacles=obstacles,
                 perception=perception, **radii)


def load_world(path: str | os.PathLike[str]) -> World:
    """The world of a scenario file (the rest of the file is not read).

    Raises
    ------
    ScenarioError
    """
    file = os.fspath(path)
    data = read_yaml(file)
    if not isinstance(data, Mapping):
        raise ScenarioError(file, '', f'the top level must be a mapping, got {type(data).__name__}')
    return read_world(Reader(file), data, os.path.dirname(os.path.abspath(file)))
