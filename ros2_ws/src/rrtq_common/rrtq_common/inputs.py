"""A node's inputs, each subscription feeding the node's lock-step gate.

/odom, which every node of a step reads, is taken as bytes and read by
:func:`rrtq_common.conversions.read_odometry` (its header, pose and velocity) instead of
being deserialised whole: the gate then holds an ``OdometryReading``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, NamedTuple

from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile

from rrtq_common.conversions import read_odometry, stamp_ns
from rrtq_common.lockstep import StepGate

__all__ = ['Input', 'subscribe_inputs', 'READERS']

READERS: dict[type, Callable[[bytes], Any]] = {Odometry: read_odometry}
"""Message types taken raw, and what reads their bytes (the reading has ``header``)."""


class Input(NamedTuple):
    """One stamped input: its key in the gate, its message type, topic and QoS."""

    key: str
    msg_type: type
    topic: str
    qos: QoSProfile


def subscribe_inputs(node: Node, gate: StepGate, inputs: Iterable[Input]) -> None:
    """Subscribe ``node`` to ``inputs``; every message goes to ``gate`` by its header stamp."""
    for key, msg_type, topic, qos in inputs:
        reader = READERS.get(msg_type)
        node.create_subscription(msg_type, topic, _filer(gate, key, reader), qos,
                                 raw=reader is not None)


def _filer(gate: StepGate, key: str,
           reader: Callable[[bytes], Any] | None = None) -> Callable[[Any], None]:
    if reader is not None:
        def read(data: bytes) -> None:
            msg = reader(data)
            gate.add(key, stamp_ns(msg.header.stamp), msg)
        return read

    def callback(msg: Any) -> None:
        gate.add(key, stamp_ns(msg.header.stamp), msg)
    return callback
