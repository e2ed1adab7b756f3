#!/usr/bin/env python3
"""Time of one vf_lpc control step (and of the guidance rollout), on this machine.

The controller runs the offline closed loop (RRT^X path, guidance, vf_lpc, exact plant)
on the rover of mass 70 kg with acceleration bumps, from a model identified at 40 kg, so
the GP fills its dictionary. Each step is timed in CPU time of this process
(``time.process_time``): the machine is shared by several sessions, and wall time there
mostly measures waiting for a core (the load average is recorded beside). Horizons
N = 10, 20, 30 with the GP, N = 20 without it, and N = 20 with one actor-critic iteration
per step instead of two, in one run (compare the ratios). Usage::

    .venv/bin/python benchmarks/vf_lpc_step.py
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from common import save

from rrtq_bringup.vf_lpc_harness import Bump, identify_by_probing, rover_plant, run_closed_loop
from rrtq_controller.vf_lpc import LPCConfig
from rrtq_planner.guidance import GuidanceConfig, GuidanceTrack
from rrtq_common.geometry import polygon_from_circle

OBSTACLES = [polygon_from_circle((8.0, 1.0), 1.5, 16),
             np.array([[12.0, -6.0], [14.0, -6.0], [14.0, 3.0], [12.0, 3.0]]),
             polygon_from_circle((18.0, 5.0), 1.0, 16)]
BUMPS = [Bump((5.0, -1.0), 3.0, (0.0, 2.0)), Bump((20.0, 2.0), 3.0, (-1.5, 1.5))]


def main() -> int:
    model = identify_by_probing(rover_plant(40.0), np.random.default_rng(0))
    rows = []
    load = os.getloadavg()[0]
    for n, comp, its in ((10, True, 2), (20, True, 2), (30, True, 2), (20, False, 2),
                         (20, True, 1)):
        r = run_closed_loop(rover_plant(70.0), model, OBSTACLES, (0.0, 0.0), (25.0, 5.0),
                            (-5.0, 30.0, -10.0, 15.0), bumps=BUMPS, duration=40.0,
                            lpc=LPCConfig(horizon_steps=n, compensate=comp, iterations=its),
                            clock=time.process_time)
        ms = r.step_ms
        rows.append({'N': n, 'gp': comp, 'iterations': its, 'steps': int(ms.size),
                     'median_ms': float(np.median(ms)),
                     'p95_ms': float(np.percentile(ms, 95)), 'max_ms': float(ms.max()),
                     'reached': bool(r.reached), 'collided': bool(r.collided)})
        print(rows[-1], flush=True)
    track = GuidanceTrack(r.path, [], GuidanceConfig(mode='gvf'))
    t0 = time.process_time()
    curve = track.roll(r.path[0])
    roll_us = (time.process_time() - t0) / len(curve.points) * 1e6
    base = next(x for x in rows if x['N'] == 20 and x['gp'])['median_ms']
    table = [f'CPU time per control step; load average {load:.1f} on {os.cpu_count()} cores '
             'during the run.', '',
             '| N | GP | iterations | steps | median ms | p95 ms | max ms | / N=20 GP median |',
             '|---|---|---|---|---|---|---|---|']
    for x in rows:
        table.append(f"| {x['N']} | {'yes' if x['gp'] else 'no'} | {x['iterations']} | "
                     f"{x['steps']} | "
                     f"{x['median_ms']:.2f} | {x['p95_ms']:.2f} | {x['max_ms']:.2f} | "
                     f"{x['median_ms'] / base:.2f} |")
    table.append('')
    table.append(f'Guidance rollout (eq. 17, no obstacles near), CPU: {roll_us:.0f} µs per curve '
                 f'point of {track.config.step} m.')
    table.append('Target: median <= 5 ms at N = 20 (with GP).')
    save('vf_lpc_step', {'rows': rows, 'guidance_us_per_point': roll_us, 'load_average': load},
         '\n'.join(table))
    print('\n'.join(table))
    return 0


if __name__ == '__main__':
    sys.exit(main())
