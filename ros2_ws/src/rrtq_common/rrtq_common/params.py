"""A node's ROS parameters, declared from a settings dataclass and turned back into it.

:func:`declare_config` declares one read-only parameter per field of a dataclass made with
:func:`rrtq_common.settings.setting`: its type from the annotation, its description and
range from the field's metadata, its default from the field. A setting whose default is
None or empty is declared by type alone (ROS parameters carry neither None nor the type
of an empty list): left unset, it takes the dataclass default when the dataclass is built.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter

from rrtq_common.executors import make_executor
from rrtq_common.readiness import announce_when_matched
from rrtq_common.run import Dimensions
from rrtq_common.settings import Kind, from_parameters, kind_of, parameter_value, spec

__all__ = ['declare_config', 'spin_node']

T = TypeVar('T')

_TYPES = {
    Kind.BOOL: Parameter.Type.BOOL, Kind.INT: Parameter.Type.INTEGER,
    Kind.FLOAT: Parameter.Type.DOUBLE, Kind.STR: Parameter.Type.STRING,
    Kind.ENUM: Parameter.Type.STRING, Kind.INTS: Parameter.Type.INTEGER_ARRAY,
    Kind.FLOATS: Parameter.Type.DOUBLE_ARRAY, Kind.STRS: Parameter.Type.STRING_ARRAY,
    Kind.MATRIX: Parameter.Type.DOUBLE_ARRAY,
}


def _descriptor(cls: type, name: str, ptype: Parameter.Type) -> ParameterDescriptor:
    meta, kind = spec(cls, name), kind_of(cls, name)
    text = meta.describe()
    if kind.enum is not None:
        text += '; one of ' + ' | '.join(str(e.value) for e in kind.enum)
    descriptor = ParameterDescriptor(name=name, type=ptype.value, description=text,
                                     read_only=True)
    if meta.low is None and meta.high is None:
        return descriptor
    if kind.kind is Kind.INT:
        descriptor.integer_range = [IntegerRange(
            from_value=int(meta.low) if meta.low is not None else -2**63,
            to_value=int(meta.high) if meta.high is not None else 2**63 - 1, step=0)]
    elif kind.kind is Kind.FLOAT:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(meta.low) if meta.low is not None else -math.inf,
            to_value=float(meta.high) if meta.high is not None else math.inf, step=0.0)]
    return descriptor


def _default(cls: type, field: dataclasses.Field[Any]) -> Any:
    if field.default is not dataclasses.MISSING:
        return parameter_value(cls, field.name, field.default)
    if field.default_factory is not dataclasses.MISSING:
        return parameter_value(cls, field.name, field.default_factory())
    return None


def declare_config(node: Node, cls: type[T], dims: Dimensions | None = None,
                   exclude: tuple[str, ...] = (), **given: Any) -> T:
    """Declare the fields of ``cls`` as parameters of ``node`` and build ``cls`` from them.

    Parameters
    ----------
    node : rclpy.node.Node
    cls : type
        A frozen dataclass of settings.
    dims : Dimensions, optional
        Sizes of the matrices among the fields (default: the rover's).
    exclude : tuple of str
        Fields that are not parameters of this node: their default applies.
    **given
        Fields the node takes from elsewhere (another setting, the world file).

    Raises
    ------
    ValueError
        A value out of its range, or a matrix that does not fit its dimensions.
    """
    values: dict[str, Any] = {}
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        if field.name in exclude or field.name in given:
            continue
        ptype = _TYPES[kind_of(cls, field.name).kind]
        default = _default(cls, field)
        value = node.declare_parameter(field.name, ptype if default is None else default,
                                       _descriptor(cls, field.name, ptype)).value
        values[field.name] = (list(value) if isinstance(value, Sequence)
                             and not isinstance(value, str) else value)
    built = from_parameters(cls, values, dataclasses.asdict(dims or Dimensions()), **given)
    assert isinstance(built, cls)
    return built


TEARDOWN_S = 10.0
"""s a node process may take to tear down once its spin has ended (see :func:`spin_node`)."""


def _exit_stuck() -> None:
    print(f'teardown took more than {TEARDOWN_S:g} s (the middleware): exiting', file=sys.stderr,
          flush=True)
    os._exit(0)


def spin_node(factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """The standard ``main()`` of a node process: init, spin, clean shutdown.

    The node spins on the run's executor (:func:`rrtq_common.executors.make_executor`).
    SIGINT and SIGTERM end the spin through rclpy's signal handlers; the node is
    destroyed in every case so that it can finish its outputs (the recorder closes
    its file in ``destroy_node``).

    The teardown is bounded: past :data:`TEARDOWN_S` the process exits anyway. Fast DDS can
    spin for as long as a discovery callback is in flight when a participant is deleted
    (eProsima/Fast-DDS#6513). Seen: a spawner whose orchestrator had been killed stayed
    at 100 % of a core in ``DomainParticipant::set_listener`` under ``rcl_node_fini``
    for minutes, an orphan. A node finishes its own outputs first in ``destroy_node``
    (the recorder its file), before the middleware's part.
    """
    rclpy.init(args=args)
    node = None
    executor = make_executor()
    try:
        node = factory()
        announce_when_matched(node)
        executor.add_node(node)
        # Not executor.spin(): Jazzy's EventsExecutor.spin() keeps a core busy and never
        # lets the signal handlers run (rrtq_common.executors).
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        watchdog = threading.Timer(TEARDOWN_S, _exit_stuck)
        watchdog.daemon = True
        watchdog.start()
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        watchdog.cancel()
