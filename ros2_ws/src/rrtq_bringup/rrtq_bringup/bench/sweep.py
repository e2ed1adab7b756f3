"""``rrtq bench --set KEY=V1,V2 ...``: the configurations of a sweep.

Each ``--set`` names a scenario key by its dotted path (``controller.R``,
``planner.steer_distance``, ``safety.margin``) and a comma-separated list of
values, each read as a YAML scalar (``0.02`` a number, ``true`` a boolean,
``conformal`` a string; a bracketed flow list such as ``[1, 2]`` stays one
value).  The sweep runs the cross product of all the lists, every configuration
over the same seeds.  A configuration is the base scenario's YAML mapping with
its values set *before* validation, so an unknown key or a bad value is the
scenario loader's error, naming the file and the key.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
from typing import Any

import yaml

__all__ = ['Setting', 'SweepError', 'apply', 'configurations', 'label', 'parse_setting']

# Keys the bench itself writes into every run's scenario.
RESERVED = ('name', 'seed', 'obstacles')


class SweepError(ValueError):
    """A ``--set`` argument that cannot be read (bad input, exit code 2)."""


@dataclasses.dataclass(frozen=True)
class Setting:
    """One ``--set KEY=V1,V2``: a dotted key and its values, in order."""

    key: str
    values: tuple[Any, ...]


def _split(text: str) -> list[str]:
    """Split at the commas outside brackets and braces."""
    parts, depth, current = [], 0, ''
    for ch in text:
        if ch in '[{':
            depth += 1
        elif ch in ']}':
            depth -= 1
        if ch == ',' and depth == 0:
            parts.append(current)
            current = ''
        else:
            current += ch
    parts.append(current)
    return parts


def parse_setting(text: str) -> Setting:
    """Read ``KEY=V1,V2,...``.

    Raises
    ------
    SweepError
        Without ``=``, with an empty key or value, a reserved key, or a value
        that is not YAML.
    """
    key, sep, rest = text.partition('=')
    key = key.strip()
    where = f'--set {text!r}'
    if not sep or not key or any(not part for part in key.split('.')):
        raise SweepError(f'{where}: expected KEY=V1,V2,... with a dotted scenario key')
    if key.split('.')[0] in RESERVED:
        raise SweepError(f'{where}: {key.split(".")[0]!r} is set by the bench for every run')
    values = []
    for raw in _split(rest):
        if not raw.strip():
            raise SweepError(f'{where}: empty value')
        try:
            values.append(yaml.safe_load(raw))
        except yaml.YAMLError as exc:
            raise SweepError(f'{where}: {raw!r} is not a YAML value ({exc})') from None
    return Setting(key, tuple(values))


def configurations(settings: list[Setting]) -> list[dict[str, Any]]:
    """The cross product: one ``{key: value}`` per configuration, the last key varying fastest.

    No settings give the one configuration without overrides.

    Raises
    ------
    SweepError
        When a key is set twice.
    """
    keys = [s.key for s in settings]
    for key in keys:
        if keys.count(key) > 1:
            raise SweepError(f'--set {key}: given more than once (list all its values in one)')
    return [dict(zip(keys, combo)) for combo in itertools.product(*(s.values for s in settings))]


def apply(document: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """A copy of the scenario mapping with each dotted key set (missing levels created).

    Raises
    ------
    SweepError
        When a level on the way is present but not a mapping.
    """
    out = copy.deepcopy(document)
    for key, value in overrides.items():
        node = out
        parts = key.split('.')
        for depth, part in enumerate(parts[:-1]):
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise SweepError(f'--set {key}: {".".join(parts[:depth + 1])} is not a mapping '
                                 'in the scenario')
            node = child
        node[parts[-1]] = copy.deepcopy(value)
    return out


def _text(value: Any) -> str:
    """A value as it would be typed after ``=``."""
    if isinstance(value, str):
        return value
    dumped = yaml.safe_dump(value, default_flow_style=True).strip()
    return dumped.removesuffix('...').strip()


def label(overrides: dict[str, Any]) -> str:
    """``controller.R=0.02, safety.margin=conformal`` ('base' without overrides)."""
    if not overrides:
        return 'base'
    return ', '.join(f'{k}={_text(v)}' for k, v in overrides.items())
