"""Declare ROS parameters once, with descriptors, and read their values."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter

_TYPES = {
    bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER, float: Parameter.Type.DOUBLE,
    str: Parameter.Type.STRING,
}
_ARRAY_TYPES = {
    float: Parameter.Type.DOUBLE_ARRAY, str: Parameter.Type.STRING_ARRAY,
    int: Parameter.Type.INTEGER_ARRAY, bool: Parameter.Type.BOOL_ARRAY,
}


def declare(node: Node, name: str, default: Any, description: str,
            low: float | None = None, high: float | None = None,
            element: type | None = None, read_only: bool = True) -> Any:
    """Declare ``name`` with a descriptor (description, range) and return its value.

    ``default`` gives the type; for arrays pass ``element`` (``float`` or ``str``),
    since an empty list carries no type. Ranges apply to numbers only.
    """
    if isinstance(default, (list, tuple)):
        ptype = _ARRAY_TYPES[element or type(default[0])]
        default = list(default)
    else:
        ptype = _TYPES[type(default)]
    descriptor = ParameterDescriptor(name=name, type=ptype.value, description=description,
                                     read_only=read_only)
    if low is not None or high is not None:
        if ptype == Parameter.Type.INTEGER:
            descriptor.integer_range = [IntegerRange(
                from_value=int(low if low is not None else -2**63),
                to_value=int(high if high is not None else 2**63 - 1), step=0)]
        else:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(low if low is not None else -1e300),
                to_value=float(high if high is not None else 1e300), step=0.0)]
    value = node.declare_parameter(name, Parameter(name, ptype, default).value,
                                   descriptor).value
    return list(value) if isinstance(value, Sequence) and not isinstance(value, str) else value


def spin_node(factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """The standard ``main()`` of a node process: init, spin, clean shutdown.

    SIGINT and SIGTERM end the spin through rclpy's signal handlers; the node is
    destroyed in every case so that it can finish its outputs (the recorder closes
    its file in ``destroy_node``).
    """
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
