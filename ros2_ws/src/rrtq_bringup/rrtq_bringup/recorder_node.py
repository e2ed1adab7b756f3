"""Recorder node: every topic, discovered as it appears, into a rosbag2-style MCAP."""

from __future__ import annotations

import importlib
import inspect
import pathlib
import time
from collections.abc import Callable
from typing import Any

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile,
                       ReliabilityPolicy)

from rrtq_bringup.recording import (INFINITE_DURATION, SCENARIO_METADATA, McapRecorder,
                                    QosOffer, RecorderConfig)
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.params import declare_config, spin_node


def message_class(type_name: str) -> type:
    """``pkg/msg/Type`` -> the generated Python class."""
    package, interface, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{interface}'), name)


def _duration(d: Duration) -> tuple[int, int]:
    ns = d.nanoseconds
    if ns >= INFINITE_DURATION[0] * 10**9 + INFINITE_DURATION[1] or ns < 0:
        return INFINITE_DURATION
    return divmod(ns, 10**9)


def offer_of(qos: QoSProfile) -> QosOffer:
    """A publisher's offered profile in rmw's policy names."""
    return QosOffer(
        history='keep_all' if qos.history == HistoryPolicy.KEEP_ALL else 'keep_last',
        depth=qos.depth,
        reliability=('best_effort' if qos.reliability == ReliabilityPolicy.BEST_EFFORT
                     else 'reliable'),
        durability=('transient_local' if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
                    else 'volatile'),
        deadline=_duration(qos.deadline), lifespan=_duration(qos.lifespan),
        liveliness=('manual_by_topic' if qos.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC
                    else 'automatic'),
        liveliness_lease_duration=_duration(qos.liveliness_lease_duration),
        avoid_ros_namespace_conventions=qos.avoid_ros_namespace_conventions)


def request_for(offers: list[QosOffer]) -> QoSProfile:
    """The subscription profile that connects to every offer (rosbag2's adaptation)."""
    reliable = bool(offers) and all(o.reliability == 'reliable' for o in offers)
    latched = bool(offers) and all(o.durability == 'transient_local' for o in offers)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=1000,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


DRAIN_LIMIT = 1000
# The signature rclpy reads to hand a subscription callback the message info as well.
_WITH_INFO = inspect.Signature([inspect.Parameter(name, inspect.Parameter.POSITIONAL_ONLY)
                                for name in ('data', 'info')])


def with_info(handle: Callable[[bytes, Any], None]) -> Callable[..., None]:
    """A raw subscription callback that gets the message info, under either executor.

    rclpy's Executor calls it with (data, info), Jazzy's EventsExecutor with the one tuple
    (data, info); rclpy reads the signature to decide whether to pass the info at all.
    """
    def callback(*args) -> None:
        data, info = args if len(args) == 2 else args[0]
        handle(data, info)
    callback.__signature__ = _WITH_INFO  # type: ignore[attr-defined]
    return callback


class RecorderNode(Node):
    """Subscribe raw to every topic that has a publisher and append it to ``output``."""

    def __init__(self, **kwargs) -> None:
        super().__init__('recorder', **NODE_OPTIONS, **kwargs)
        config = declare_config(self, RecorderConfig)
        self.recorder = McapRecorder(config.output, flush_period_s=config.flush_period_s)
        if config.scenario:
            self.recorder.add_metadata(SCENARIO_METADATA, {
                'path': config.scenario, 'yaml': pathlib.Path(config.scenario).read_text()})
        self._recorded: dict[str, object] = {}
        self._timer = self.create_timer(config.discovery_period_s, self.discover)
        self.discover()

    def discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._recorded or len(types) != 1:
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue
            offers = [offer_of(i.qos_profile) for i in infos]
            type_name = types[0]
            self.recorder.add_topic(topic, type_name, offers, str(infos[0].topic_type_hash))
            self._recorded[topic] = self.create_subscription(
                message_class(type_name), topic, self._callback_for(topic),
                request_for(offers), raw=True)
        self.recorder.tick(time.monotonic())

    def _callback_for(self, topic: str):
        def callback(data: bytes, info) -> None:
            self._write(topic, data, info)
            # Drain what else is queued on this topic now: one executor round trip per
            # message would cap the recorder at a few thousand messages per second.
            self._drain(topic, DRAIN_LIMIT)
        return with_info(callback)

    def _drain(self, topic: str, limit: int | None) -> None:
        """Write what is queued on ``topic`` without the executor (at most ``limit``)."""
        subscription = self._recorded[topic]
        count = 0
        while limit is None or count < limit:
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, True)
            if taken is None:
                break
            self._write(topic, *taken)
            count += 1

    def _write(self, topic: str, data: bytes, info) -> None:
        self.recorder.write(topic, data, info['received_timestamp'], info['source_timestamp'],
                            time.monotonic())

    def destroy_node(self) -> None:
        # What arrived but was not yet taken (a recorder behind on a busy machine when the
        # run ends) is written before the file closes: the last odometry, the last state.
        for topic in list(self._recorded):
            try:
                self._drain(topic, None)
            except Exception as exc:  # noqa: BLE001 - a closing file beats a lost recording
                self.get_logger().warning(f'could not drain {topic} at shutdown: {exc}')
        self.recorder.finish()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(RecorderNode, args)


if __name__ == '__main__':
    main()
