"""A node's inputs, each subscription feeding the node's lock-step gate."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, NamedTuple

from rclpy.node import Node
from rclpy.qos import QoSProfile

from rrtq_common.conversions import stamp_ns
from rrtq_common.lockstep import StepGate

__all__ = ['Input', 'subscribe_inputs']


class Input(NamedTuple):
    """One stamped input: its key in the gate, its message type, topic and QoS."""

    key: str
    msg_type: type
    topic: str
    qos: QoSProfile


def subscribe_inputs(node: Node, gate: StepGate, inputs: Iterable[Input]) -> None:
    """Subscribe ``node`` to ``inputs``; every message goes to ``gate`` by its header stamp."""
    for key, msg_type, topic, qos in inputs:
        node.create_subscription(msg_type, topic, _filer(gate, key), qos)


def _filer(gate: StepGate, key: str) -> Callable[[Any], None]:
    def callback(msg: Any) -> None:
        gate.add(key, stamp_ns(msg.header.stamp), msg)
    return callback
