#!/usr/bin/env python3
"""The guiding level on the Otte and forest environments: curvature bound and deadlocks.

For M. Otte's ``rand_Static`` (3 planner seeds) and the 100 x 100 m forests of
:mod:`rrtq_bringup.forest` (seeds 1, 2; 300 trees, as ``scenarios/envs/make_forest.py``
writes them), an RRT^X path is planned on the obstacles grown by the robot radius (0.5 m),
the composite field's curve is rolled out from the start to the goal, and the reference
sampled every 0.05 s. Reported: how the
rollout ended (reached / stalled), the share of reference samples with v² kappa <= a_max
(curvature from the samples' circumradius, speed from central differences), the largest
v² kappa / a_max, the time to the goal against the path length at v_max, and the smallest
clearance to the grown obstacles. Usage::

    .venv/bin/python benchmarks/vf_lpc_guidance.py
"""

from __future__ import annotations

import sys

import numpy as np
import yaml

from common import save

from rrtq_bringup.forest import forest_yaml
from rrtq_common.geometry import polygon_from_circle
from rrtq_common.polygon_set import PolygonSet
from rrtq_planner import routes
from rrtq_planner.guidance import (CurveStatus, GuidanceConfig, GuidanceTrack, sample_in_time,
                                   speed_profile)
from rrtq_planner.shortcut import Shortener
from rrtq_testing.paths import OTTE, read_otte

RADIUS = 0.5
CFG = GuidanceConfig(mode='gvf')


def forest(seed: int):
    sc = yaml.safe_load(forest_yaml(seed))
    trees = [polygon_from_circle(o['circle']['center'], o['circle']['radius'], 16)
             for o in sc['obstacles']]
    return trees, np.array(sc['start'], float), np.array(sc['goal'], float), (0, 100, 0, 100)


def otte():
    polygons = read_otte(OTTE / 'rand_Static.txt')
    start, goal = np.array([35.0, -40.0]), np.array([-40.0, 40.0])
    return polygons, start, goal, routes.default_bounds(polygons, start, goal, RADIUS)


def evaluate(name, polys, start, goal, bounds, seed, iterations):
    grown = routes.grow(polys, RADIUS)
    planner = routes.make_planner(grown, start, goal, bounds, RADIUS, seed)
    planner.run(iterations)
    path = routes.shortest_route(planner, start, Shortener(grown))
    track = GuidanceTrack(path, grown, CFG)
    curve = track.roll(start)
    speeds = speed_profile(curve.points, CFG, 0.0, curve.status is CurveStatus.REACHED)
    ref = sample_in_time(curve.points, speeds, CFG.dt, 40000)
    p = ref.positions
    a = np.linalg.norm(p[1:-1] - p[:-2], axis=1)
    b = np.linalg.norm(p[2:] - p[1:-1], axis=1)
    c = np.linalg.norm(p[2:] - p[:-2], axis=1)
    u, w = p[1:-1] - p[:-2], p[2:] - p[1:-1]
    with np.errstate(divide='ignore', invalid='ignore'):
        kappa = np.where(a * b * c > 0, 2 * np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
                         / (a * b * c), 0.0)
    v = c / (2 * CFG.dt)
    moving = np.hypot(*ref.velocities.T)[1:-1] > 0
    lat = v[moving] ** 2 * kappa[moving]
    arrive = ref.t[np.flatnonzero(np.hypot(*ref.velocities.T) > 0)[-1] + 1]
    referee = PolygonSet(grown)
    length = routes.path_length(path)
    return {'environment': name, 'seed': seed, 'status': str(curve.status),
            'virtual_obstacles': len(track.field.virtual), 'path_m': round(length, 2),
            'samples': int(moving.sum()), 'share_within': float(np.mean(lat <= CFG.a_max)),
            'worst_ratio': float(lat.max() / CFG.a_max), 'time_s': float(arrive),
            'time_at_vmax_s': length / CFG.v_max,
            'min_clearance_m': float(min(referee.nearest(q)[0] for q in curve.points))}


def main() -> int:
    rows = []
    for seed in (3, 4, 5):
        rows.append(evaluate('otte rand_Static', *otte(), seed, 2000))
        print(rows[-1], flush=True)
    for fs in (1, 2):
        rows.append(evaluate(f'forest seed {fs}', *forest(fs), 1, 2000))
        print(rows[-1], flush=True)
    table = ['| environment | planner seed | rollout | path (m) | samples | v²κ <= a_max | '
             'worst v²κ / a_max | time to goal (s) | path / v_max (s) | min clearance (m) |',
             '|---|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        table.append(f"| {r['environment']} | {r['seed']} | {r['status']} | {r['path_m']:.1f} | "
                     f"{r['samples']} | {100 * r['share_within']:.2f} % | "
                     f"{r['worst_ratio']:.2f} | {r['time_s']:.1f} | {r['time_at_vmax_s']:.1f} | "
                     f"{r['min_clearance_m']:.2f} |")
    table += ['', f'a_max = {CFG.a_max} m/s², v_max = {CFG.v_max} m/s, reactive width '
              f'{CFG.reactive_width} m, repulsive offset {CFG.repulsive_offset} m, step '
              f'{CFG.step} m; clearance to the obstacles grown by the robot radius '
              f'{RADIUS} m. Target: >= 99 % within, never stalled.']
    save('vf_lpc_guidance', {'rows': rows}, '\n'.join(table))
    print('\n'.join(table))
    return 0


if __name__ == '__main__':
    sys.exit(main())
