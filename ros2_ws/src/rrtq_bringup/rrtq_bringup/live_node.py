"""Live view: every topic of the running graph, served over the Foxglove WebSocket protocol.

``rrtq run --live [PORT]`` adds this node. It discovers topics as the recorder does and
subscribes to each raw, and the official Foxglove SDK (``foxglove-sdk``) serves them on
``ws://127.0.0.1:PORT`` (loopback only, never another address): one channel per topic,
encoding ``cdr`` with the ``ros2msg`` schema text the recording carries, so Foxglove decodes
the messages exactly as it decodes the recording. The node is a reader only, outside the
lock-step chain: in lock-step the run goes as fast as it runs and the view follows (what
the viewer misses is dropped by the SDK's per-client backlog, never waited for); to watch
at the pace of the simulation, run with ``--speed 1.0``.
"""

from __future__ import annotations

import foxglove
from rclpy.node import Node

from rrtq_bringup.recorder_node import message_class, offer_of, request_for, with_info
from rrtq_bringup.recording import schema_text
from rrtq_bringup.viz import LIVE_HOST, LiveConfig
from rrtq_common.params import declare_config, spin_node


class LiveNode(Node):
    """Forward every topic's CDR bytes to a Foxglove WebSocket server on 127.0.0.1."""

    def __init__(self, **kwargs) -> None:
        super().__init__('live', **kwargs)
        config = declare_config(self, LiveConfig)
        self.context_fg = foxglove.Context()
        self.server = foxglove.start_server(name='rrtq', host=LIVE_HOST, port=config.port,
                                            context=self.context_fg)
        self.get_logger().info(f'live view on ws://{LIVE_HOST}:{self.server.port}')
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
            self._readers.append(self.create_subscription(
                message_class(type_name), topic, self._forward(channel),
                request_for([offer_of(i.qos_profile) for i in infos]), raw=True))

    @staticmethod
    def _forward(channel: foxglove.Channel):
        def callback(data: bytes, info) -> None:
            channel.log(data, log_time=info['received_timestamp'])
        return with_info(callback)

    def destroy_node(self) -> None:
        self.server.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(LiveNode, args)


if __name__ == '__main__':
    main()
