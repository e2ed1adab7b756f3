"""Test harness for in-process executors: isolated contexts, message collection, waits.

Each test gets its own ``rclpy.Context`` on its own ``ROS_DOMAIN_ID`` (held for the
test by the same lock files the orchestrator uses), with DDS on loopback, so tests
can run in parallel and never hear each other or anything else.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile

from rrtq_bringup.orchestrator import domain_id


@contextlib.contextmanager
def isolated_context() -> Iterator[tuple[rclpy.Context, SingleThreadedExecutor, int]]:
    """A fresh context and executor on a private domain; shut down afterwards."""
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    with domain_id() as domain:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        executor = SingleThreadedExecutor(context=context)
        try:
            yield context, executor, domain
        finally:
            for node in list(executor.get_nodes()):
                executor.remove_node(node)
                node.destroy_node()
            executor.shutdown()
            context.try_shutdown()


class Collector:
    """Keeps every message received on one topic, with its receive order."""

    def __init__(self, node: Node, msg_type: type, topic: str, qos: QoSProfile | int = 100,
                 raw: bool = False) -> None:
        self.messages: list[Any] = []
        self.subscription = node.create_subscription(msg_type, topic, self.messages.append,
                                                     qos, raw=raw)

    def __len__(self) -> int:
        return len(self.messages)


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool],
               timeout_s: float = 10.0) -> bool:
    """Spin ``executor`` until ``condition()`` holds; False if ``timeout_s`` passes first."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.01)
    return True


def wait_for_messages(executor: SingleThreadedExecutor, collector: Collector, count: int,
                      timeout_s: float = 10.0) -> list[Any]:
    """Spin until ``collector`` holds ``count`` messages; raise TimeoutError otherwise."""
    if not spin_until(executor, lambda: len(collector) >= count, timeout_s):
        raise TimeoutError(f'{len(collector)} of {count} messages within {timeout_s} s')
    return collector.messages
