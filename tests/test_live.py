"""`rrtq run --live PORT`: a Foxglove WebSocket client on 127.0.0.1 watches the run.

The client speaks the protocol itself (the ``websockets`` package): server info, the
advertised channels, a subscription, and the binary message frames, whose CDR payloads are
decoded with mcap_ros2's decoder from the schema text the server advertised. It offers the
two subprotocol names the Foxglove app offers: the official SDK's server answers to
``foxglove.sdk.v1`` only (a client that offers nothing but the older name
``foxglove.websocket.v1`` is refused, which the test checks too, since docs/design.md says
so). The listening sockets are read from /proc/net.
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
from websockets.exceptions import InvalidStatus

ROOT = pathlib.Path(__file__).resolve().parents[1]

# A plant test (no planner), long enough in lock-step to be watched; the test ends it with
# SIGINT (as Ctrl-C would) once it has seen what it wants.
SCENARIO = """
name: live
seed: 2
bounds: {x: [-40, 40], y: [-40, 40]}
start: [0.0, 0.0]
goal: [30.0, 30.0]
duration: 300.0
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


async def watch(port: int, deadline: float) -> tuple[dict, dict, dict, bool]:
    """Connect, read server info and adverts, subscribe to WANTED, decode one message each.

    Also: whether a client offering only ``foxglove.websocket.v1`` is refused.
    """
    while True:
        try:
            ws = await connect(f'ws://127.0.0.1:{port}', subprotocols=OFFERED, max_size=None)
            break
        except OSError:
            assert time.monotonic() < deadline, 'the live server never accepted a connection'
            await asyncio.sleep(0.2)
    try:
        async with connect(f'ws://127.0.0.1:{port}', subprotocols=['foxglove.websocket.v1']):
            old_name_refused = False
    except InvalidStatus as refusal:
        old_name_refused = refusal.response.status_code == 400
    async with ws:
        assert ws.subprotocol == 'foxglove.sdk.v1'
        info, channels, decoded, subscribed = None, {}, {}, {}
        factory = DecoderFactory()
        while time.monotonic() < deadline and len(decoded) < len(WANTED):
            frame = await asyncio.wait_for(ws.recv(), timeout=max(0.1, deadline - time.monotonic()))
            if isinstance(frame, str):
                op = json.loads(frame)
                if op['op'] == 'serverInfo':
                    info = op
                elif op['op'] == 'advertise':
                    for channel in op['channels']:
                        channels[channel['topic']] = channel
                        if channel['topic'] in WANTED and channel['topic'] not in subscribed.values():
                            sub_id = len(subscribed) + 1
                            subscribed[sub_id] = channel['topic']
                            await ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                                {'id': sub_id, 'channelId': channel['id']}]}))
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
    return info, channels, decoded, old_name_refused


def test_live_view_serves_the_running_graph_on_loopback_only(tmp_path):
    scenario = tmp_path / 'live.yaml'
    scenario.write_text(SCENARIO)
    port = free_port()
    proc = subprocess.Popen([str(ROOT / 'scripts/rrtq'), 'run', str(scenario), '--out',
                             str(tmp_path / 'run'), '--mode', 'composed', '--live', str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        info, channels, decoded, old_name_refused = asyncio.run(
            watch(port, time.monotonic() + 60.0))
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
    assert info is not None and info['name'] == 'rrtq'
    assert {'/odom', '/cmd_force', '/viz/obstacles/truth', '/tf'} <= set(channels)
    assert channels['/odom']['schemaName'] == 'nav_msgs/msg/Odometry'
    assert all(c['encoding'] == 'cdr' and c['schemaEncoding'] == 'ros2msg'
               for c in channels.values())
    assert set(decoded) == set(WANTED), f'received only {sorted(decoded)}'
    assert decoded['/odom'].child_frame_id == 'base_link'
    assert [m.text for m in decoded['/viz/obstacles/truth'].markers] == ['post']
    assert decoded['/tf'].transforms[0].child_frame_id == 'base_link'
    assert old_name_refused
    # The run went on while it was watched, and its recording has what the viewer saw.
    assert summary['sim_time_s'] > 0.0
    assert (tmp_path / 'run' / 'run.mcap').exists()
