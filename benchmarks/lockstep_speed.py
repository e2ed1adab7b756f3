"""Lock-step speed: the transport floor, the plant-only graph and the paper scenario.

In one run, side by side (absolute numbers on a shared machine are noisy, ratios less so):

- the floor: two nodes on one executor in this process, an Odometry -> WrenchStamped
  ping-pong on the graph's stream QoS, round trips per second, with rclpy's
  ``SingleThreadedExecutor`` and with ``rclpy.experimental.EventsExecutor``;
- ``rrtq run`` of scenarios/plant_only.yaml (60 s of sim time) and of
  scenarios/rrtqx_paper.yaml (to the goal), composed and in processes, on each executor
  (``RRTQ_EXECUTOR``, :mod:`rrtq_common.executors`): steps per second from the summary's
  ``sim_speedup`` (start-up excluded), as a fraction of each floor, and the CPU time of
  the whole run (every process, start-up included) per step.

The load average is recorded before and after: the machine is shared.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time

from common import ROOT, save

EXECUTORS = ('single', 'events')
PING_PONG_S = 3.0


def ping_pong(executor_name: str, seconds: float) -> float:
    """Round trips per second of an Odometry -> WrenchStamped ping-pong on one executor."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from nav_msgs.msg import Odometry
    from rclpy.node import Node

    from rrtq_bringup.orchestrator import domain_id
    from rrtq_common import qos
    from rrtq_common.executors import make_executor

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['RRTQ_EXECUTOR'] = executor_name
    with domain_id() as domain:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        executor = make_executor(context)
        ping, pong = Node('ping', context=context), Node('pong', context=context)
        odom_pub = ping.create_publisher(Odometry, '/odom', qos.STREAM)
        cmd_pub = pong.create_publisher(WrenchStamped, '/cmd_force', qos.STREAM)
        count = [0]

        def on_odom(msg: Odometry) -> None:
            cmd = WrenchStamped()
            cmd.header.stamp = msg.header.stamp
            cmd_pub.publish(cmd)

        def on_cmd(_msg: WrenchStamped) -> None:
            count[0] += 1
            odom = Odometry()
            odom.header.stamp.sec = count[0]
            odom_pub.publish(odom)

        pong.create_subscription(Odometry, '/odom', on_odom, qos.STREAM)
        ping.create_subscription(WrenchStamped, '/cmd_force', on_cmd, qos.STREAM)
        executor.add_node(ping)
        executor.add_node(pong)
        deadline = time.monotonic() + 10.0
        while (odom_pub.get_subscription_count() < 1 or cmd_pub.get_subscription_count() < 1) \
                and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        odom_pub.publish(Odometry())
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            executor.spin_once(timeout_sec=0.1)
        rate = count[0] / (time.monotonic() - start)
        for node in (ping, pong):
            executor.remove_node(node)
        executor.shutdown()
        ping.destroy_node()
        pong.destroy_node()
        context.try_shutdown()
    return rate


def run(scenario: str, mode: str, executor_name: str, out: str) -> dict:
    """One ``rrtq run``: its summary's speed, and the CPU time of all its processes."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', scenario, '--out', out, '--mode', mode,
                    '--overwrite'], capture_output=True,
                   env={**os.environ, 'RRTQ_EXECUTOR': executor_name})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    summary = json.load(open(f'{out}/summary.json'))
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    steps_per_s = summary['sim_speedup'] / 0.05 if summary['sim_speedup'] else 0.0
    return {'outcome': summary['outcome'], 'steps': summary['steps'],
            'sim_speedup': summary['sim_speedup'], 'steps_per_s': steps_per_s,
            'cpu_s': cpu, 'cpu_ms_per_step': 1e3 * cpu / max(summary['steps'], 1)}


def main() -> None:
    load = [os.getloadavg()[0]]
    floor = {}
    for name in EXECUTORS:
        floor[name] = ping_pong(name, PING_PONG_S)
        print(f'ping-pong {name}: {floor[name]:.0f} round trips/s', file=sys.stderr)
    plant = (ROOT / 'scenarios/plant_only.yaml').read_text().replace('duration: 30.0',
                                                                     'duration: 60.0')
    graphs: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        plant_path = f'{tmp}/plant_only_60s.yaml'
        open(plant_path, 'w').write(plant)
        for graph, scenario in (('plant only', plant_path),
                                ('paper scenario', str(ROOT / 'scenarios/rrtqx_paper.yaml'))):
            for mode in ('composed', 'processes'):
                for name in EXECUTORS:
                    result = run(scenario, mode, name, f'{tmp}/{len(graphs)}')
                    result['of_floor'] = {f: result['steps_per_s'] / floor[f] for f in EXECUTORS}
                    graphs[f'{graph}, {mode}, {name}'] = result
                    print(f'{graph} {mode} {name}: {result["steps_per_s"]:.0f} steps/s, '
                          f'{result["cpu_ms_per_step"]:.1f} CPU ms/step', file=sys.stderr)
    load.append(os.getloadavg()[0])
    rows = [f'| ping-pong floor | — | {name} | {rate:.0f} round trips/s | 1 | — | — |'
            for name, rate in floor.items()]
    for key, r in graphs.items():
        graph, mode, name = key.split(', ')
        rows.append(f"| {graph} | {mode} | {name} | {r['steps_per_s']:.0f} "
                    f"({r['sim_speedup']:.1f}x real time) | {r['of_floor']['single']:.3f} / "
                    f"{r['of_floor']['events']:.3f} | {r['cpu_ms_per_step']:.1f} | "
                    f"{r['outcome']} |")
    table = (f'Load average (1 min) {load[0]:.1f} before, {load[1]:.1f} after.\n\n'
             '| graph | mode | executor | steps/s | of the floor (single / events) | '
             'CPU ms per step (all processes, start-up incl.) | outcome |\n'
             '|---|---|---|---|---|---|---|\n' + '\n'.join(rows))
    save('lockstep_speed', {'floor_round_trips_per_s': floor, 'graphs': graphs,
                            'load_average': load}, table)


if __name__ == '__main__':
    main()
