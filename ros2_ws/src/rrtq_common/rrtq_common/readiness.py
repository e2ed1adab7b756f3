"""The start-up handshake of a run: a node says when its writers have reached their readers.

The simulator takes the first step only once every reader of every per-step topic is
connected, so that no node, and not the recorder, misses a step. What the graph API
reports (``count_subscribers``) is not enough for that: discovery announces a reader to
the graph before the writer has matched it, and a writer only delivers to the readers it
has matched. Seen on CI: a 4 s run whose recording had no ``/disturbance`` at all and
whose supervisor saw none of the 81 commands, while the simulator's graph counts had said
that every reader was there.

A writer's own matched count (``Publisher.get_subscription_count``) is the ground truth,
and only the writer's node can read it. So each node that writes per-step topics is given
the number of readers each of them must reach (the parameter :data:`PARAMETER`, built by
``rrtq_bringup.graph``), and publishes its name on :data:`rrtq_common.topics.GRAPH_READY`
(latched) once its writers have matched that many; the simulator waits for every name it
was told to expect (``SimulatorConfig.ready_from``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from rrtq_common import topics
from rrtq_common.run import READY_PARAMETER

__all__ = ['PARAMETER', 'QOS', 'Announcer', 'announce_when_matched', 'expectations']

PARAMETER = READY_PARAMETER
"""A node's parameter: ``topic:count`` per topic it writes, the readers it must reach."""
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=32,
                 reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Latched, deep enough for every node's one announcement to wait in a reader's queue."""
PERIOD_S = 0.02
"""s of wall time between two looks at the matched counts."""
WARN_AFTER_S = 5.0
"""s of wall time after which a node still waiting says for which readers."""


def expectations(items: Sequence[str], name: str = PARAMETER) -> dict[str, int]:
    """``['/cmd_force:3', ...]`` -> ``{'/cmd_force': 3, ...}`` (``name``: the parameter's)."""
    found = {}
    for item in items:
        topic, sep, count = item.rpartition(':')
        if not sep or not topic or not count.isdigit():
            raise ValueError(f'{name}: {item!r} is not topic:count')
        found[topic] = int(count)
    return found


class Announcer:
    """Publishes ``node``'s name once its writers of ``expected`` have matched their readers.

    Looks on a steady wall timer: a node on sim time has no clock before the first step.
    """

    def __init__(self, node: Node, expected: Mapping[str, int]) -> None:
        self.node = node
        self.expected = dict(expected)
        self.announced = False
        self._pub = node.create_publisher(String, topics.GRAPH_READY, QOS)
        self._clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._since = self._clock.now()
        self._timer = node.create_timer(PERIOD_S, self.check, clock=self._clock)

    def missing(self) -> dict[str, int]:
        """Topic -> readers matched so far, for each topic still short of its count."""
        matched = dict.fromkeys(self.expected, 0)
        for pub in self.node.publishers:
            if pub.topic_name in matched:
                matched[pub.topic_name] = max(matched[pub.topic_name],
                                              pub.get_subscription_count())
        return {t: n for t, n in matched.items() if n < self.expected[t]}

    def check(self) -> None:
        if self.announced:
            return
        if missing := self.missing():
            waited = (self._clock.now() - self._since).nanoseconds * 1e-9
            if waited > WARN_AFTER_S:
                short = ', '.join(f'{t} {n}/{self.expected[t]}' for t, n in missing.items())
                self.node.get_logger().warning(
                    f'{waited:.0f} s: writers still short of their readers: {short}',
                    throttle_duration_sec=WARN_AFTER_S)
            return
        self.announced = True
        self._timer.cancel()
        self._pub.publish(String(data=self.node.get_name()))


def announce_when_matched(node: Node) -> Announcer | None:
    """Declare :data:`PARAMETER` on ``node``; start its :class:`Announcer` if it is set."""
    if node.has_parameter(PARAMETER):
        items = node.get_parameter(PARAMETER).value
    else:
        items = node.declare_parameter(PARAMETER, Parameter.Type.STRING_ARRAY, ParameterDescriptor(
            name=PARAMETER, type=Parameter.Type.STRING_ARRAY.value, read_only=True,
            description='topic:count per per-step topic this node writes: announce on '
                        f'{topics.GRAPH_READY} once its writer has matched that many readers '
                        '(the start-up handshake; set by the run\'s graph)')).value
    if not items:
        return None
    return Announcer(node, expectations(items))
