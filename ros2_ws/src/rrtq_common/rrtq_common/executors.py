"""The executor a run's nodes spin on, and the options its nodes are made with.

A lock-step step is a chain of a dozen messages through seven nodes, so a run's speed is
set by what one callback dispatch costs. rclpy's ``SingleThreadedExecutor`` rebuilds its
wait set from every entity of every node in Python on each ``spin_once``;
``rclpy.experimental.EventsExecutor`` (C++, event queue) does not. Both dispatch the
callbacks one at a time in one thread, so a lock-step run gives the same bytes on either
(``benchmarks/lockstep_speed.py`` measures both).

Jazzy's ``EventsExecutor`` differs from rclpy's executors in four ways the nodes allow
for: it calls a subscription callback that takes the message info with one argument, the
tuple (message, info) (the recorder's callback takes either); an exception raised in a
callback reaches ``spin_once`` as ``SystemError: null argument to internal routine``,
its own traceback only in the log line rclpy writes; the timers of a node removed from
it may still fire before it notices (so a node is destroyed only when nothing spins any
more); and its ``spin()`` keeps a core busy and never returns to Python, so SIGINT and
SIGTERM go unheard (a node process spins with ``spin_once`` in a loop instead).
``RRTQ_EXECUTOR=single`` in the environment selects rclpy's ``SingleThreadedExecutor``
instead, for comparison.

The nodes of a run are configured by their parameters files or overrides, never at run
time: they are made without parameter services (:data:`NODE_OPTIONS`).
"""

from __future__ import annotations

import os
from typing import Any

import rclpy
from rclpy.executors import Executor, SingleThreadedExecutor

__all__ = ['NODE_OPTIONS', 'make_executor']

NODE_OPTIONS: dict[str, Any] = {'start_parameter_services': False}
"""Keyword arguments of ``rclpy.node.Node`` for every node of the graph."""


def make_executor(context: rclpy.Context | None = None) -> Executor:
    """The executor of a run (``EventsExecutor``; ``RRTQ_EXECUTOR=single``: rclpy's)."""
    if os.environ.get('RRTQ_EXECUTOR', 'events') == 'single':
        return SingleThreadedExecutor(context=context)
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)
