"""Recorder throughput: the MCAP writer core alone, and the recorder node across processes.

- core: McapRecorder.write of serialized Odometry messages (zstd chunks, indexes).
- node: a publisher process sends Odometry as fast as it can on a reliable topic; the
  recorder node, in its own process, records it; throughput is messages received over
  the span of their receive times.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import textwrap
import time

import numpy as np
from rclpy.serialization import serialize_message

from common import save
from rrtq_bringup.orchestrator import domain_id, ros_env
from rrtq_bringup.recording import McapRecorder, QosOffer
from rrtq_common.conversions import odometry_msg

N_CORE = 100_000
N_NODE = 20_000

PUBLISHER = textwrap.dedent('''
    import sys, time, numpy as np, rclpy
    from nav_msgs.msg import Odometry
    from rrtq_common import qos
    from rrtq_common.conversions import odometry_msg
    rclpy.init()
    node = rclpy.create_node('blaster')
    pub = node.create_publisher(Odometry, '/odom', qos.STREAM)
    while pub.get_subscription_count() < 1:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(1.0)
    count, rate = int(sys.argv[1]), float(sys.argv[2])
    start = time.perf_counter()
    for k in range(count):
        if rate > 0:
            while time.perf_counter() < start + k / rate:
                pass
        pub.publish(odometry_msg(k, np.array([k, 0.0, 0.0, 0.0])))
    time.sleep(3.0)
''')


def core(tmp: str) -> dict:
    data = [serialize_message(odometry_msg(k, np.random.default_rng(k).normal(size=4)))
            for k in range(1000)]
    rec = McapRecorder(f'{tmp}/core.mcap')
    rec.add_topic('/odom', 'nav_msgs/msg/Odometry', [QosOffer()], 'RIHS01_' + '0' * 64)
    start = time.perf_counter()
    for k in range(N_CORE):
        rec.write('/odom', data[k % 1000], k, k, time.monotonic())
    rec.finish()
    wall = time.perf_counter() - start
    return {'messages_per_s': N_CORE / wall, 'mb_per_s': rec.byte_count / wall / 1e6,
            'message_bytes': len(data[0]),
            'file_mb': os.path.getsize(f'{tmp}/core.mcap') / 1e6}


def node(tmp: str, rate: float, count: int) -> dict:
    from mcap.reader import make_reader
    out = f'{tmp}/node{rate:g}.mcap'
    with domain_id() as domain:
        env = ros_env(domain)
        recorder = subprocess.Popen([sys.executable, '-m', 'rrtq_bringup.recorder_node',
                                     '--ros-args', '-p', f'output:={out}'], env=env)
        time.sleep(1.0)
        subprocess.run([sys.executable, '-c', PUBLISHER, str(count), str(rate)], env=env,
                       check=True)
        recorder.send_signal(2)
        recorder.wait(timeout=30)
    times, size = [], 0
    for _, _channel, message in make_reader(open(out, 'rb')).iter_messages(topics=['/odom']):
        times.append(message.log_time)
        size += len(message.data)
    span = (times[-1] - times[0]) * 1e-9
    return {'offered_per_s': rate or None, 'received': len(times), 'sent': count,
            'messages_per_s': len(times) / span,
            'mb_per_s': size / span / 1e6}


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        results = {'core': core(tmp), 'node_flood': node(tmp, 0.0, N_NODE),
                   'node_2000hz': node(tmp, 2000.0, 10_000)}
    c = results['core']
    table = ('| recorder | messages/s | MB/s | notes |\n|---|---|---|---|\n'
             f"| core (McapRecorder.write) | {c['messages_per_s']:.0f} | {c['mb_per_s']:.1f} "
             f"| Odometry, {c['message_bytes']} B each, zstd chunks |\n"
             + '\n'.join(
                 f"| node, publisher in another process, {label} | {n['messages_per_s']:.0f} | "
                 f"{n['mb_per_s']:.2f} | {n['received']} of {n['sent']} received |"
                 for label, n in (('flooding', results['node_flood']),
                                  ('2000 msg/s offered', results['node_2000hz']))))
    save('recorder_throughput', results, table)


if __name__ == '__main__':
    main()
