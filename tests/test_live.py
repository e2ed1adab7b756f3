"""`rrtq run --live PORT`: a Foxglove WebSocket client on 127.0.0.1 watches the run.

The client speaks the protocol itself (the ``websockets`` package): server info, the
advertised channels, a subscription, and the binary message frames, whose CDR payloads are
decoded with mcap_ros2's decoder from the schema text the server advertised. Two clients
watch the same run at once: one offers only the protocol's older subprotocol name
``foxglove.websocket.v1`` (older Foxglove and Lichtblick releases, ws-protocol clients) and
must be answered under that name, one offers both names as the Foxglove app does and gets
``foxglove.sdk.v1`` (the official SDK's name, rrtq_bringup.ws_alias). The listening sockets
are read from /proc/net.
"""

import asyncio
import json
import pathlib
import signal
import socket
import struct
import subprocess
import time

from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from rrtq_bringup.ws_alias import rename_request, rename_response

ROOT = pathlib.Path(__file__).resolve().parents[1]

# A plant test (no planner), long enough in lock-step to be watched; the test ends it with
# SIGINT (as Ctrl-C would) once it has seen what it wants.
SCENARIO = """
name: live
seed: 2
bounds: {x: [-40, 40], y: [-40, 40]}
start: [0.0, 0.0]
goal: [30.0, 30.0]
duration: 3000.0
perception_radius: 6.0
robot_radius: 0.3
plant: {model: rover, stiffness: 0.0, force_limit: 100.0}
controller:
  variant: open_loop
  forces: [[0.0, 20.0, 10.0], [5.0, -20.0, 10.0], [10.0, 0.0, 0.0]]
obstacles:
  - {id: post, polygon: [[3, -1], [4, -1], [4, 0], [3, 0]], known: true}
"""
OFFERED = ['foxglove.sdk.v1', 'foxglove.websocket.v1']     # as the Foxglove app offers them
OLD_ONLY = ['foxglove.websocket.v1']                         # as older clients offer it
RESUBSCRIBE_S = 3.0
WANTED = ('/odom', '/viz/obstacles/truth', '/tf')


def free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def listening(port: int) -> list[str]:
    """Local addresses of the TCP sockets listening on ``port`` (IPv4 and IPv6)."""
    found = []
    for table in ('/proc/net/tcp', '/proc/net/tcp6'):
        for line in pathlib.Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.split(':')
            if state == '0A' and int(hex_port, 16) == port:          # 0A: LISTEN
                if len(address) == 8:
                    found.append(socket.inet_ntoa(struct.pack('<I', int(address, 16))))
                else:
                    found.append('ipv6:' + address)
    return found


async def watch(port: int, deadline: float, offered: list[str]) -> tuple[str, dict, dict, dict]:
    """Connect offering ``offered``; server info, adverts, one decoded message of each WANTED.

    Returns the subprotocol the server chose, the server info, the channels and the
    decoded messages.
    """
    while True:
        try:
            ws = await connect(f'ws://127.0.0.1:{port}', subprotocols=offered, max_size=None)
            break
        except OSError:
            assert time.monotonic() < deadline, 'the live server never accepted a connection'
            await asyncio.sleep(0.2)
    async with ws:
        chosen = ws.subprotocol
        info, channels, decoded, subscribed, asked = None, {}, {}, {}, {}

        async def subscribe(topic: str) -> None:
            sub_id = len(subscribed) + 1
            subscribed[sub_id], asked[topic] = topic, time.monotonic()
            await ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': sub_id, 'channelId': channels[topic]['id']}]}))

        factory = DecoderFactory()
        while time.monotonic() < deadline and len(decoded) < len(WANTED):
            # A subscription sent right after a channel's advert is sometimes refused by the
            # SDK's server ("attempted to subscribe to unknown channel"): a client asks again
            # after RESUBSCRIBE_S without data, as a viewer's panel would.
            for topic, when in list(asked.items()):
                if topic not in decoded and time.monotonic() - when > RESUBSCRIBE_S:
                    await subscribe(topic)
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=0.5)
            except asyncio.TimeoutError:
                continue
            except ConnectionClosed:         # the run ended: what was seen is judged below
                break
            if isinstance(frame, str):
                op = json.loads(frame)
                if op['op'] == 'serverInfo':
                    info = op
                elif op['op'] == 'advertise':
                    for channel in op['channels']:
                        channels[channel['topic']] = channel
                        if channel['topic'] in WANTED and channel['topic'] not in asked:
                            await subscribe(channel['topic'])
                continue
            if frame[0] != 0x01:                               # 0x01: message data
                continue
            sub_id, _log_time = struct.unpack_from('<IQ', frame, 1)
            topic = subscribed[sub_id]
            channel = channels[topic]
            if topic in decoded:
                continue
            # The decoder factory caches by schema id: one id per channel.
            schema = Schema(id=channel['id'], name=channel['schemaName'],
                            encoding=channel['schemaEncoding'], data=channel['schema'].encode())
            decoded[topic] = factory.decoder_for(channel['encoding'], schema)(frame[13:])
    return chosen, info, channels, decoded


async def both(port: int, deadline: float) -> list[tuple[str, dict, dict, dict]]:
    """The two clients at once, as two viewers of the same run."""
    return list(await asyncio.gather(watch(port, deadline, OLD_ONLY), watch(port, deadline, OFFERED)))


def test_live_view_serves_the_running_graph_on_loopback_only(tmp_path):
    scenario = tmp_path / 'live.yaml'
    scenario.write_text(SCENARIO)
    port = free_port()
    proc = subprocess.Popen([str(ROOT / 'scripts/rrtq'), 'run', str(scenario), '--out',
                             str(tmp_path / 'run'), '--mode', 'composed', '--live', str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        seen = dict(zip((OLD_ONLY[0], OFFERED[0]), asyncio.run(both(port, time.monotonic() + 60.0))))
        addresses = listening(port)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            stdout, stderr = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            stdout, stderr = proc.communicate()
    summary = json.loads(stdout)
    assert summary['outcome'] == 'interrupted', stderr
    assert addresses == ['127.0.0.1']
    chosen = {offer: seen[offer][0] for offer in seen}
    assert chosen == {'foxglove.websocket.v1': 'foxglove.websocket.v1',    # the name it asked for
                      'foxglove.sdk.v1': 'foxglove.sdk.v1'}
    for _, info, channels, decoded in seen.values():
        assert info is not None and info['name'] == 'rrtq'
        assert {'/odom', '/cmd_force', '/viz/obstacles/truth', '/tf'} <= set(channels)
        assert channels['/odom']['schemaName'] == 'nav_msgs/msg/Odometry'
        assert all(c['encoding'] == 'cdr' and c['schemaEncoding'] == 'ros2msg'
                   for c in channels.values())
        assert set(decoded) == set(WANTED), f'received only {sorted(decoded)} of {sorted(channels)}'
        assert decoded['/odom'].child_frame_id == 'base_link'
        assert [m.text for m in decoded['/viz/obstacles/truth'].markers] == ['post']
        assert decoded['/tf'].transforms[0].child_frame_id == 'base_link'
    # The run went on while it was watched, and its recording has what the viewer saw.
    assert summary['sim_time_s'] > 0.0
    assert (tmp_path / 'run' / 'run.mcap').exists()


def test_the_alias_renames_only_an_offer_of_the_older_name_alone():
    """The handshake rewrite of rrtq_bringup.ws_alias, on the head bytes themselves."""
    head = (b'GET / HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nUpgrade: websocket\r\n'
            b'Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n')
    renamed, did = rename_request(head)
    assert did and b'Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n' in renamed
    assert renamed.replace(b'foxglove.sdk.v1', b'foxglove.websocket.v1') == head
    both = head.replace(b'foxglove.websocket.v1', b'foxglove.sdk.v1, foxglove.websocket.v1')
    assert rename_request(both) == (both, False)
    other = head.replace(b'foxglove.websocket.v1', b'chat')
    assert rename_request(other) == (other, False)
    answer = b'HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n'
    assert rename_response(answer) == answer.replace(b'foxglove.sdk.v1', b'foxglove.websocket.v1')
