"""Settings: frozen-dataclass fields that carry their default, unit and range.

Each core declares its configuration once, as a frozen dataclass whose fields are made
with :func:`setting`. Everything else reads that one definition: a node declares its ROS
parameters from it (:mod:`rrtq_common.params`, with descriptors from the metadata), the
orchestrator hands it to the node (:func:`to_parameters`), and the scenario reader checks
a file's values against the same ranges. A default written twice drifts; a sentinel for
"unset" hides a missing value: an optional setting is ``None`` and says what ``None`` means.
"""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = [
    'Kind', 'Setting', 'SettingError', 'setting', 'like', 'spec', 'kind_of', 'check',
    'parameter_value', 'to_parameters', 'from_parameters',
]

META = 'rrtq'


@dataclasses.dataclass(frozen=True)
class Setting:
    """What a field's metadata says about it.

    Attributes
    ----------
    doc : str
        One line for people (the ROS parameter's description).
    unit : str
        Unit of the value ('' when it has none).
    low, high : float or None
        Range of a number (or of each number of a sequence); None: unbounded.
    low_open, high_open : bool
        The bound itself is excluded.
    rows : str or None
        Matrices: the dimension (``n``, ``m`` or ``q`` of :class:`rrtq_common.run.Dimensions`)
        that gives the number of rows; a ROS parameter holds it row-major and flat.
    columns : int or None
        Tables of fixed width (rows of ``columns`` numbers), flat in a ROS parameter.
    """

    doc: str
    unit: str = ''
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    rows: str | None = None
    columns: int | None = None

    def describe(self) -> str:
        """The description with the unit and the range."""
        text = self.doc + (f' [{self.unit}]' if self.unit else '')
        bounds = self.range_text()
        return f'{text}; {bounds}' if bounds else text

    def range_text(self) -> str:
        """The range in words ('' when unbounded)."""
        parts = []
        if self.low is not None:
            parts.append(f'{">" if self.low_open else ">="} {self.low:g}')
        if self.high is not None:
            parts.append(f'{"<" if self.high_open else "<="} {self.high:g}')
        return ' and '.join(parts)

    def violation(self, value: float) -> str | None:
        """Why ``value`` is out of range, or None when it is in range."""
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return f'must be {">" if self.low_open else ">="} {self.low:g}, got {value}'
        if self.high is not None and (value >= self.high if self.high_open
                                      else value > self.high):
            return f'must be {"<" if self.high_open else "<="} {self.high:g}, got {value}'
        return None


class SettingError(ValueError):
    """A setting's value is out of its range.

    Attributes
    ----------
    name : str
        The field.
    message : str
        What is wrong (``must be > 0, got 0.0``).
    """

    def __init__(self, name: str, message: str) -> None:
        super().__init__(f'{name} {message}')
        self.name = name
        self.message = message


def setting(default: Any = dataclasses.MISSING, *, doc: str, unit: str = '',
            low: float | None = None, high: float | None = None, low_open: bool = False,
            high_open: bool = False, rows: str | None = None, columns: int | None = None,
            factory: Any = dataclasses.MISSING) -> Any:
    """A dataclass field with its :class:`Setting` (no default: the setting is required)."""
    meta = Setting(doc, unit, low, high, low_open, high_open, rows, columns)
    return dataclasses.field(default=default, default_factory=factory, metadata={META: meta})


def like(cls: type, name: str) -> Any:
    """The field ``name`` of the dataclass ``cls`` again, default and metadata alike.

    For a configuration that hands a setting on to another core's: the default stays
    written once, where the setting is used.
    """
    field = _fields(cls)[name]
    return dataclasses.field(default=field.default, default_factory=field.default_factory,
                             metadata=field.metadata)


def spec(cls: type, name: str) -> Setting:
    """The :class:`Setting` of field ``name`` of ``cls``."""
    return typing.cast(Setting, _fields(cls)[name].metadata[META])


def _fields(cls: type) -> dict[str, dataclasses.Field[Any]]:
    return {f.name: f for f in dataclasses.fields(cls)}


class Kind(enum.Enum):
    """How a setting travels as a ROS parameter."""

    BOOL = 'bool'
    INT = 'int'
    FLOAT = 'float'
    STR = 'str'
    ENUM = 'enum'            # a str, one of the enum's values
    INTS = 'ints'
    FLOATS = 'floats'
    STRS = 'strs'
    MATRIX = 'matrix'        # floats, row-major (rows from Setting.rows or .columns)


@dataclasses.dataclass(frozen=True)
class FieldKind:
    """A field's :class:`Kind`, its enum class (ENUM), and what it is built back as."""

    kind: Kind
    enum: type[enum.Enum] | None = None
    optional: bool = False
    array: bool = False       # MATRIX: a read-only numpy array (else nested tuples)
    scalar_ok: bool = False   # MATRIX: one number stands for itself (scalar times identity)


def kind_of(cls: type, name: str) -> FieldKind:
    """The :class:`FieldKind` of field ``name`` of ``cls``, from its annotation."""
    hint = typing.get_type_hints(cls)[name]
    meta = spec(cls, name)
    optional = False
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        optional = len(args) < len(typing.get_args(hint))
        hint = args[0] if len(args) == 1 else Any
    if meta.rows is not None or meta.columns is not None:
        return FieldKind(Kind.MATRIX, optional=optional, array=hint is np.ndarray,
                         scalar_ok=hint is Any)
    scalars = {bool: Kind.BOOL, int: Kind.INT, float: Kind.FLOAT, str: Kind.STR}
    if hint in scalars:
        return FieldKind(scalars[hint], optional=optional)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return FieldKind(Kind.ENUM, enum=hint, optional=optional)
    if typing.get_origin(hint) is tuple:
        element = typing.get_args(hint)[0]
        arrays = {int: Kind.INTS, float: Kind.FLOATS, str: Kind.STRS}
        if element in arrays:
            return FieldKind(arrays[element], optional=optional)
    raise TypeError(f'{cls.__name__}.{name}: no ROS parameter kind for {hint!r}')


def check(config: Any, finite: bool = False) -> None:
    """Raise :class:`SettingError` for the first field whose value is out of its range.

    With ``finite``, a float field that is nan or infinite is out of range too.
    """
    for field in dataclasses.fields(config):
        meta = field.metadata.get(META)
        value = getattr(config, field.name)
        if finite and isinstance(value, float) and not np.isfinite(value):
            raise SettingError(field.name, f'must be finite, got {value}')
        if meta is None or value is None or (meta.low is None and meta.high is None):
            continue
        for number in np.ravel(np.asarray(value, dtype=float)):
            problem = meta.violation(float(number))
            if problem is not None:
                raise SettingError(field.name, problem)


def _flat(value: Any) -> list[float]:
    return [float(v) for v in np.ravel(np.asarray(value, dtype=float))]


def parameter_value(cls: type, name: str, value: Any) -> Any:
    """``value`` of field ``name`` of ``cls`` as a ROS parameter value (None: not representable).

    None and empty sequences have no ROS parameter value: the node's declaration leaves
    them unset, and the dataclass default applies.
    """
    if value is None:
        return None
    kind = kind_of(cls, name).kind
    if kind is Kind.ENUM:
        return value.value
    if kind in (Kind.BOOL, Kind.STR):
        return value
    if kind is Kind.INT:
        return int(value)
    if kind is Kind.FLOAT:
        return float(value)
    if kind is Kind.INTS:
        out: list[Any] = [int(v) for v in value]
    elif kind is Kind.STRS:
        out = [str(v) for v in value]
    else:
        out = _flat(value)
    return out or None


def to_parameters(config: Any, exclude: tuple[str, ...] = ()) -> dict[str, Any]:
    """``config``'s fields as ROS parameter values (what the orchestrator hands a node)."""
    out: dict[str, Any] = {}
    for field in dataclasses.fields(config):
        value = parameter_value(type(config), field.name, getattr(config, field.name))
        if field.name not in exclude and value is not None:
            out[field.name] = value
    return out


def _matrix(flat: list[float], cls: type, name: str, dims: Mapping[str, int]) -> Any:
    kind, meta = kind_of(cls, name), spec(cls, name)
    if kind.scalar_ok and len(flat) == 1:
        return float(flat[0])
    table = np.asarray(flat, dtype=float)
    if meta.rows is not None:
        rows = dims[meta.rows]
        if rows <= 0 or table.size % rows:
            raise ValueError(f'parameter {name}: {table.size} values do not fill {rows} rows')
        table = table.reshape(rows, -1)
    else:
        table = table.reshape(-1, typing.cast(int, meta.columns))
    if kind.array or kind.scalar_ok:
        table.setflags(write=False)
        return table
    return tuple(tuple(float(v) for v in row) for row in table)


def from_parameters(cls: type, values: Mapping[str, Any], dims: Mapping[str, int],
                    **given: Any) -> Any:
    """Build ``cls`` from ROS parameter values (None: not set, the default applies).

    ``given`` supplies fields the node does not take as parameters.
    """
    kwargs: dict[str, Any] = dict(given)
    for name, value in values.items():
        if value is None:
            continue
        kind = kind_of(cls, name)
        if kind.kind is Kind.ENUM:
            assert kind.enum is not None
            kwargs[name] = kind.enum(value)
        elif kind.kind in (Kind.INTS, Kind.FLOATS, Kind.STRS):
            kwargs[name] = tuple(value)
        elif kind.kind is Kind.MATRIX:
            kwargs[name] = _matrix(list(value), cls, name, dims)
        elif kind.kind is Kind.FLOAT:
            kwargs[name] = float(value)
        else:
            kwargs[name] = value
    return cls(**kwargs)

