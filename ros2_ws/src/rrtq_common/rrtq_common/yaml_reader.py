"""Strict YAML for the scenario files: every problem names the file and the dotted key.

:class:`Reader` gives typed access to a parsed document and raises :class:`ScenarioError`
with the key path (``plant.mass``, ``obstacles[2].polygon``), so the orchestrator can
print it and exit with code 2 before anything starts; :meth:`Reader.setting` checks a
value against the range its settings dataclass declares. :func:`read_yaml` rejects
duplicate keys, which PyYAML would keep silently (the last one).
"""

from __future__ import annotations

import dataclasses
import enum
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np
import yaml

from rrtq_common.geometry import as_polygon
from rrtq_common.settings import Kind, kind_of, spec

__all__ = ['ScenarioError', 'Reader', 'join', 'frozen', 'read_yaml', 'field_default']


class ScenarioError(Exception):
    """A scenario file is unusable.

    Attributes
    ----------
    file : str
        The scenario file.
    key : str
        Dotted path of the offending key ('' for the file as a whole).
    message : str
        What is wrong.
    """

    def __init__(self, file: str, key: str, message: str) -> None:
        super().__init__(file, key, message)
        self.file = file
        self.key = key
        self.message = message

    def __str__(self) -> str:
        return f'{self.file}: {self.key}: {self.message}'


def join(parent: str, child: str) -> str:
    return f'{parent}.{child}' if parent else child


def frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


class Reader:
    """Typed access to the parsed YAML, raising ScenarioError with the key path."""

    def __init__(self, file: str) -> None:
        self.file = file

    def error(self, key: str, message: str) -> ScenarioError:
        return ScenarioError(self.file, key, message)

    def mapping(self, value: Any, key: str, allowed: tuple[str, ...] | None) -> dict[Any, Any]:
        """A mapping whose keys are all in ``allowed`` (None: any keys)."""
        if not isinstance(value, Mapping):
            raise self.error(key, f'expected a mapping, got {type(value).__name__}')
        for k in value if allowed is not None else ():
            if allowed is not None and k not in allowed:
                allowed_list = ', '.join(allowed)
                raise self.error(join(key, str(k)), f'unknown key (allowed: {allowed_list})')
        return dict(value)

    def setting(self, data: Mapping[str, Any], name: str, cls: type, section: str = '',
                *, allow_inf: bool = False, key: str | None = None) -> Any:
        """Setting ``name`` of the dataclass ``cls`` from ``data``, checked against its range.

        Absent (or null), it is the field's default; else a number within the range the
        field's metadata declares.

        ``key`` is the setting's key in the file when it differs from ``name``.
        """
        value = data.get(key or name)
        key = join(section, key or name)
        if value is None:
            return field_default(cls, name)
        meta, kind = spec(cls, name), kind_of(cls, name).kind
        number = self.number(value, key, allow_inf=allow_inf)
        if kind is Kind.INT and number != int(number):
            where = meta.range_text()
            raise self.error(key, f'must be an integer{" " + where if where else ""}, '
                             f'got {number}')
        problem = meta.violation(number)
        if problem is not None:
            raise self.error(key, problem)
        return int(number) if kind is Kind.INT else number

    def number(
        self,
        value: Any,
        key: str,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        allow_inf: bool = False,
    ) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            hint = ''
            if isinstance(value, str):
                hint = ' (YAML 1.1 reads 1e3 as a string: write 1.0e3)'
            raise self.error(key, f'expected a number, got {type(value).__name__} {value!r}{hint}')
        x = float(value)
        if math.isnan(x) or (math.isinf(x) and not (allow_inf and x > 0)):
            raise self.error(key, f'must be finite, got {x}')
        if positive and not x > 0.0:
            raise self.error(key, f'must be > 0, got {x}')
        if nonnegative and not x >= 0.0:
            raise self.error(key, f'must be >= 0, got {x}')
        return x

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(key, f'expected true or false, got {value!r}')
        return value

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(key, f'expected a non-empty string, got {value!r}')
        return value

    def choice(self, value: Any, key: str, enum_type: type[enum.StrEnum]) -> Any:
        options = [e.value for e in enum_type]
        if not isinstance(value, str) or value not in options:
            raise self.error(key, f"must be one of {', '.join(options)}, got {value!r}")
        return enum_type(value)

    def matrix(self, value: Any, key: str, shape: tuple[int | None, int | None]) -> np.ndarray:
        rows_ok = isinstance(value, list) and all(isinstance(r, list) and r for r in value)
        if not (rows_ok and value):
            raise self.error(key, 'expected a matrix: a list of rows, each a list of numbers')
        for i, row in enumerate(value):
            if len(row) != len(value[0]):
                raise self.error(key, f'row {i} has {len(row)} entries, row 0 has {len(value[0])}')
            for j, v in enumerate(row):
                self.number(v, f'{key}[{i}][{j}]')
        mat = np.array(value, dtype=float)
        want = tuple(s if s is not None else mat.shape[i] for i, s in enumerate(shape))
        if mat.shape != want:
            got = f'{mat.shape[0]}x{mat.shape[1]}'
            raise self.error(key, f'expected shape {want[0]}x{want[1]}, got {got}')
        return mat

    def weight(self, value: Any, key: str, size: int, *, definite: bool) -> np.ndarray:
        """A weight matrix: a scalar (times identity) or a full symmetric matrix."""
        if isinstance(value, list):
            mat = self.matrix(value, key, (size, size))
        else:
            mat = self.number(value, key, positive=definite, nonnegative=True) * np.eye(size)
        scale = max(1.0, float(np.abs(mat).max()))
        if not np.allclose(mat, mat.T, rtol=0.0, atol=1e-9 * scale):
            raise self.error(key, 'must be symmetric')
        low = float(np.linalg.eigvalsh(mat).min())
        if definite and not low > 1e-12 * scale:
            raise self.error(key, f'must be positive definite (smallest eigenvalue {low:.3g})')
        if not definite and low < -1e-12 * scale:
            raise self.error(key, f'must be positive semi-definite (lowest eigenvalue {low:.3g})')
        return mat

    def point(self, value: Any, key: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) != 2:
            raise self.error(key, f'expected a point [x, y], got {value!r}')
        return np.array([self.number(v, f'{key}[{i}]') for i, v in enumerate(value)])

    def polygon(self, value: Any, key: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) < 3:
            raise self.error(key, 'expected a list of at least 3 vertices [x, y]')
        poly = np.array([self.point(v, f'{key}[{i}]') for i, v in enumerate(value)])
        try:
            return as_polygon(poly)
        except ValueError as exc:
            raise self.error(key, str(exc)) from None


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that rejects duplicate mapping keys (PyYAML keeps the last silently)."""


def _construct_mapping(loader: _StrictLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    loader.flatten_mapping(node)
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            duplicate = key in seen
            seen.add(key)
        except TypeError:
            continue  # unhashable key: construct_mapping reports it
        if duplicate:
            raise yaml.constructor.ConstructorError(
                None, None, f'duplicate key {key!r}', key_node.start_mark
            )
    return loader.construct_mapping(node, deep=True)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def field_default(cls: type, name: str) -> Any:
    """The default of field ``name`` of the dataclass ``cls`` (None when it has none)."""
    for field in dataclasses.fields(cls):
        if field.name == name:
            if field.default is not dataclasses.MISSING:
                return field.default
            if field.default_factory is not dataclasses.MISSING:
                return field.default_factory()
            return None
    raise KeyError(name)


def read_yaml(path: str | os.PathLike[str]) -> Any:
    """The parsed document of a YAML file, duplicate keys rejected.

    Raises
    ------
    ScenarioError
        With key '' for an unreadable file or a YAML error.
    """
    file = os.fspath(path)
    try:
        with open(file, encoding='utf-8') as fh:
            return yaml.load(fh, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except OSError as exc:
        raise ScenarioError(file, '', f'cannot read the file: {exc.strerror or exc}') from None
    except yaml.YAMLError as exc:
        raise ScenarioError(file, '', f'YAML error: {exc}') from None
