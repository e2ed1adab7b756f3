#!/usr/bin/env python3
"""Quick timing of the RRT^X core: iterations/s around n nodes and repair time.

Environment: Otte's rand_Static.txt (35 quadrilaterals in [-50, 50]^2), robot
(35, -40) -> goal (-40, 40).  The iteration rate is measured in blocks of 100
iterations while the tree grows from 0.9 n to 1.1 n nodes (median block, CPU
time, so other load on the machine distorts it less).  Repair: at about n
nodes a box (half-sizes 1..3 m) appears centred on a random point of the
current path; the CPU time of ``add_obstacle`` (Algorithm 7 including
reduce_inconsistency) is recorded, then the box is regrown by 0.2 m in place
(as when the safety margin grows) and removed again (both timed too), and 10
more iterations run.

Usage: PYTHONPATH=ros2_ws/src/rrtq_planner .venv/bin/python benchmarks/rrtx_quick.py
       [--nodes 3000] [--delta 5] [--epsilon 0] [--sweep]
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np

from rrtq_bringup.bench.table import machine
from rrtq_common.otte import read_polygons
from rrtq_planner.rrtx import RRTX, RRTXConfig
from rrtq_testing.paths import OTTE

ENV = OTTE / "rand_Static.txt"


def make_planner(delta: float, epsilon: float, seed: int) -> RRTX:
    cfg = RRTXConfig(
        goal=(-40.0, 40.0), bounds=(-50, 50, -50, 50), steer_distance=delta, epsilon=epsilon
    )
    planner = RRTX(cfg, np.random.default_rng(seed))
    for i, poly in enumerate(read_polygons(ENV)):
        planner.add_obstacle(f"o{i}", poly)
    planner.set_robot((35.0, -40.0))
    return planner


def grow_to(planner: RRTX, n: int) -> None:
    while planner.node_count < n:
        planner.step()


def iteration_rate(planner: RRTX, n: int) -> tuple[float, float]:
    """Median and overall iterations per CPU second from 0.9 n to 1.1 n nodes."""
    grow_to(planner, int(0.9 * n))
    rates = []
    its = 0
    total = 0.0
    while planner.node_count < int(1.1 * n):
        c0 = time.process_time()
        planner.run(100)
        dc = time.process_time() - c0
        rates.append(100 / dc)
        its += 100
        total += dc
    return float(np.median(rates)), its / total


def repair_times(planner: RRTX, repairs: int, seed: int) -> dict[str, list[float]]:
    rng = np.random.default_rng(seed)
    add_ms, grow_ms, rem_ms = [], [], []
    for k in range(repairs):
        path = planner.path()
        seglen = np.linalg.norm(np.diff(path, axis=0), axis=1)
        at = int(np.searchsorted(np.cumsum(seglen) / seglen.sum(), rng.uniform(0.1, 0.9)))
        c = path[at] + rng.uniform(0, 1) * (path[at + 1] - path[at])
        h = rng.uniform(1.0, 3.0, 2)
        poly = np.array([c - h, [c[0] + h[0], c[1] - h[1]], c + h, [c[0] - h[0], c[1] + h[1]]])
        c0 = time.process_time()
        planner.add_obstacle(f"block{k}", poly)
        add_ms.append(1e3 * (time.process_time() - c0))
        c0 = time.process_time()
        planner.add_obstacle(f"block{k}", poly + 0.2 * np.sign(poly - c))  # margin grows
        grow_ms.append(1e3 * (time.process_time() - c0))
        c0 = time.process_time()
        planner.remove_obstacle(f"block{k}")
        rem_ms.append(1e3 * (time.process_time() - c0))
        planner.run(10)
    return {"add (repair)": add_ms, "regrow +0.2 m": grow_ms, "remove": rem_ms}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=3000)
    ap.add_argument("--delta", type=float, default=5.0, help="steer distance (m)")
    ap.add_argument("--epsilon", type=float, default=0.0, help="consistency tolerance (m)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repairs", type=int, default=40)
    ap.add_argument("--sweep", action="store_true", help="also iterations/s at 1k..16k nodes")
    args = ap.parse_args()

    info = machine(pathlib.Path(__file__).resolve().parents[1])
    print(f"{info['date']}  {info['cpu']}, python {info['python']}, numpy {np.__version__}, "
          f"commit {info['commit']}")
    print(f"rand_Static, delta {args.delta} m, epsilon {args.epsilon} m, seed {args.seed}")
    if args.sweep:
        planner = make_planner(args.delta, args.epsilon, args.seed)
        for n in (1000, 2000, 4000, 8000, 16000):
            med, overall = iteration_rate(planner, n)
            print(f"  n ~{n:6d}: {med:6.0f} it/s (median block), {overall:6.0f} overall, "
                  f"r(n) {planner.radius:.2f} m")
    planner = make_planner(args.delta, args.epsilon, args.seed)
    med, overall = iteration_rate(planner, args.nodes)
    print(f"iterations/s at ~{args.nodes} nodes: {med:.0f} (median of 100-iteration blocks), "
          f"{overall:.0f} overall; r(n) {planner.radius:.2f} m; cost {planner.cost():.3f} m")
    times = repair_times(planner, args.repairs, args.seed + 1)
    for name, vals in times.items():
        a = np.array(vals)
        print(f"{name:13s} CPU ms at ~{planner.node_count} nodes: median {np.median(a):.2f}, "
              f"p95 {np.percentile(a, 95):.2f}, max {a.max():.2f} (n={a.size})")


if __name__ == "__main__":
    main()
