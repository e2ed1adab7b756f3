"""Live view: every topic of the running graph, served over the Foxglove WebSocket protocol.

``rrtq run --live [PORT]`` adds this node. It discovers topics as the recorder does and
subscribes to each raw, and the official Foxglove SDK (``foxglove-sdk``) serves them,
behind :class:`rrtq_bringup.ws_alias.SubprotocolAlias` (which answers to the protocol's
older subprotocol name too), on ``ws://127.0.0.1:PORT`` (loopback only, never another
address; the SDK itself on another loopback port): one channel per topic,
encoding ``cdr`` with the ``ros2msg`` schema text the recording carries, so Foxglove decodes
the messages exactly as it decodes the recording. The node is a reader only, outside the
lock-step chain: in lock-step the run goes as fast as it runs and the view follows (what
the viewer misses is dropped by the SDK's per-client backlog, never waited for); to watch
at the pace of the simulation, run with ``--speed 1.0``.
"""

from __future__ import annotations

import threading

import foxglove
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy

from rrtq_bringup.recorder_node import message_class, offer_of, request_for, with_info
from rrtq_bringup.recording import schema_text
from rrtq_bringup.viz import LIVE_HOST, LiveConfig
from rrtq_bringup.ws_alias import OLD_NAME, SDK_NAME, SubprotocolAlias
from rrtq_common.params import declare_config, spin_node


REPLAY_DELAY_S = 0.1
"""Wall-clock delay between a viewer's subscription and the replay of a latched topic."""


class _Replay(foxglove.ServerListener):
    """The server's subscribe events, to the node's replay of latched topics."""

    def __init__(self, node: LiveNode) -> None:
        self._node = node

    def on_subscribe(self, client, channel) -> None:
        # The server calls this before the new subscription takes messages: replay a
        # moment later, off the server's thread.
        timer = threading.Timer(REPLAY_DELAY_S, self._node.replay, (channel.id,))
        timer.daemon = True
        timer.start()


class LiveNode(Node):
    """Forward every topic's CDR bytes to a Foxglove WebSocket server on 127.0.0.1."""

    def __init__(self, **kwargs) -> None:
        super().__init__('live', **kwargs)
        config = declare_config(self, LiveConfig)
        self.context_fg = foxglove.Context()
        listener = SubprotocolAlias.bind(config.port)      # the user's port, bound first
        self._latched: dict[int, tuple[foxglove.Channel, bytes, int]] = {}
        self._lock = threading.Lock()
        self.server = foxglove.start_server(name='rrtq', host=LIVE_HOST, port=0,
                                            context=self.context_fg,
                                            server_listener=_Replay(self))
        self.alias = SubprotocolAlias(listener, self.server.port).start()
        self.get_logger().info(f'live view on ws://{LIVE_HOST}:{self.alias.port} '
                               f'(subprotocol {SDK_NAME} or {OLD_NAME})')
        self._channels: dict[str, foxglove.Channel] = {}
        self._readers: list[object] = []
        self.create_timer(config.discovery_period_s, self.discover)
        self.discover()

    def discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._channels or len(types) != 1:
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue
            type_name = types[0]
            schema = foxglove.Schema(name=type_name, encoding='ros2msg',
                                     data=schema_text(type_name).encode())
            channel = foxglove.Channel(topic, schema=schema, message_encoding='cdr',
                                       context=self.context_fg)
            self._channels[topic] = channel
            request = request_for([offer_of(i.qos_profile) for i in infos])
            latched = request.durability == DurabilityPolicy.TRANSIENT_LOCAL
            self._readers.append(self.create_subscription(
                message_class(type_name), topic, self._forward(channel, latched), request,
                raw=True))

    def _forward(self, channel: foxglove.Channel, latched: bool):
        def callback(data: bytes, info) -> None:
            stamp = info['received_timestamp']
            if latched:
                with self._lock:
                    self._latched[channel.id()] = (channel, data, stamp)
            channel.log(data, log_time=stamp)
        return with_info(callback)

    def replay(self, channel_id: int) -> None:
        """Log a latched topic's last message again, for a viewer that just subscribed.

        A latched (transient-local) topic — the obstacle markers, the robot's disc — is
        published when it changes, so a viewer that subscribes later would see nothing
        until the next change; ROS hands a late subscriber the last message, and so does
        this (viewers that already had it get it once more, which changes nothing).
        """
        with self._lock:
            last = self._latched.get(channel_id)
        if last is not None:
            channel, data, stamp = last
            channel.log(data, log_time=stamp)

    def destroy_node(self) -> None:
        self.alias.stop()
        self.server.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(LiveNode, args)


if __name__ == '__main__':
    main()
