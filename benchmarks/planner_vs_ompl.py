#!/usr/bin/env python3
"""RRT^X against OMPL's RRTstar, InformedRRTstar and BITstar (issue 3, "Benchmarks").

1. Path cost / exact optimum after 0.1, 0.5, 1, 2 and 5 s of planning on BNeck,
   rand_Static ((35, -40) -> (-40, 40)) and seeded random forests, robot radius
   0.5 m, all planners side by side in one run.  RRT^X is configured as
   ``rrtq plan`` configures it; "raw" is the tree path, "short" the ``rrtq plan``
   post-processing (corridor candidates + shortcut/tighten, given the time
   ``rrtq plan`` would give it: 0.15/0.85 of the planning time, at least the tree path).  OMPL "raw" is the best
   solution path, "short" that path after ``PathSimplifier::simplifyMax``, the
   OMPL counterpart.  Post-processing time is excluded from the planning budget on
   both sides and reported separately.  Every planner uses the same exact
   closed-polygon collision test (see ``planner_ompl``).
2. Repair: RRT^X with the planner node's configuration (delta = 5 m) grown to
   3,000 nodes on rand_Static; a box appears across the current path; the wall
   time of ``add_obstacle`` (the whole repair) against OMPL planning from scratch
   in the new world until it reaches the repaired RRT^X cost (capped).
3. Iteration time against n (node configuration, rand_Static).

Usage: scripts/env.sh sourced, then ``python benchmarks/planner_vs_ompl.py [--quick]``.
"""

from __future__ import annotations

import argparse
import math
from importlib import metadata
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import save  # noqa: E402
from planner_ompl import PLANNERS, OmplQuery  # noqa: E402
from planner_problems import RADIUS, Problem, make_problem, problems, vo  # noqa: E402
from rrtq_planner.routes import RRTX_SHARE, grow, make_planner, shortest_route  # noqa: E402
from rrtq_planner.rrtx import RRTX, RRTXConfig  # noqa: E402
from rrtq_planner.shortcut import Shortener, path_length  # noqa: E402

CHECKPOINTS = (0.1, 0.5, 1.0, 2.0, 5.0)
CHUNK = 25


def rrtx_anytime(problem: Problem, seed: int) -> list[dict]:
    """RRT^X as ``rrtq plan`` runs it, read at each checkpoint of planning time."""
    planner = make_planner(problem.grown, problem.start, problem.goal, problem.bounds,
                           RADIUS, seed)
    shortener = Shortener(problem.grown)
    spent = 0.0
    rows = []
    for t in CHECKPOINTS:
        while spent < t:
            t0 = time.perf_counter()
            planner.run(CHUNK)
            spent += time.perf_counter() - t0
        raw = planner.cost()
        t0 = time.perf_counter()
        # As ``rrtq plan`` would with this much RRT^X time: the rest of its budget.
        deadline = t0 + t * (1.0 - RRTX_SHARE) / RRTX_SHARE
        short = (path_length(shortest_route(planner, problem.start, shortener, deadline))
                 if math.isfinite(raw) else math.inf)
        rows.append({'t': t, 'cost': raw, 'simplified': short,
                     'simplify_s': time.perf_counter() - t0, 'nodes': planner.node_count,
                     'iterations': planner.iterations})
    return rows


def cost_runs(probs: list[Problem], seeds: dict[str, list[int]]) -> list[dict]:
    runs = []
    for problem in probs:
        query = OmplQuery(problem.grown, problem.start, problem.goal, problem.bounds)
        for seed in seeds.get(problem.name, [0]):
            entry = {'problem': problem.name, 'seed': seed, 'optimum': problem.optimum,
                     'RRTX': rrtx_anytime(problem, seed)}
            for name in PLANNERS:
                entry[name] = query.anytime(name, CHECKPOINTS)
            runs.append(entry)
            last = {k: entry[k][-1]['cost'] / problem.optimum for k in ('RRTX', *PLANNERS)}
            print(f'  {problem.name} seed {seed}: 5 s raw ratios '
                  + ', '.join(f'{k} {v:.4f}' for k, v in last.items()), flush=True)
    return runs


def _median(values: list[float]) -> float:
    return float(np.median(values)) if values else math.nan


def _fmt(x: float) -> str:
    return '—' if not math.isfinite(x) else f'{x:.4f}'


def cost_table(runs: list[dict]) -> tuple[str, dict]:
    groups = {'BNeck': lambda p: p == 'BNeck', 'rand_Static': lambda p: p == 'rand_Static',
              'forests': lambda p: p.startswith('forest')}
    summary: dict = {}
    lines = []
    for group, member in groups.items():
        sel = [r for r in runs if member(r['problem'])]
        if not sel:
            continue
        lines += [f'\n**{group}** ({len(sel)} runs; median cost / optimum, raw → shortened)\n',
                  '| planner | ' + ' | '.join(f'{t:g} s' for t in CHECKPOINTS) + ' |',
                  '|---|' + '---|' * len(CHECKPOINTS)]
        summary[group] = {}
        for name in ('RRTX', *PLANNERS):
            cells = []
            summary[group][name] = {}
            for k, t in enumerate(CHECKPOINTS):
                raw = _median([r[name][k]['cost'] / r['optimum'] for r in sel])
                short = _median([r[name][k]['simplified'] / r['optimum'] for r in sel])
                solved = sum(math.isfinite(r[name][k]['cost']) for r in sel)
                summary[group][name][t] = {'raw': raw, 'short': short, 'solved': solved}
                cell = f'{_fmt(raw)} → {_fmt(short)}'
                if solved < len(sel):
                    cell += f' ({solved}/{len(sel)} solved)'
                cells.append(cell)
            lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
    post = {name: 1e3 * _median([row['simplify_s'] for r in runs for row in r[name]])
            for name in ('RRTX', *PLANNERS)}
    lines.append('\nMedian post-processing time (not in the budget): '
                 + ', '.join(f'{k} {v:.0f} ms' for k, v in post.items())
                 + ' (RRT^X: corridor candidates + shortcut/tighten; OMPL: simplifyMax).')
    its = {t: _median([r['RRTX'][k]['iterations'] for r in runs])
           for k, t in enumerate(CHECKPOINTS)}
    lines.append('Median RRT^X iterations at the checkpoints: '
                 + ', '.join(f'{t:g} s: {v:.0f}' for t, v in its.items()) + '.')
    summary['post_ms'] = post
    return '\n'.join(lines), summary


def box_across(path: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    seglen = np.linalg.norm(np.diff(path, axis=0), axis=1)
    at = int(np.searchsorted(np.cumsum(seglen) / seglen.sum(), rng.uniform(0.2, 0.8)))
    at = min(at, len(path) - 2)
    c = path[at] + rng.uniform(0.0, 1.0) * (path[at + 1] - path[at])
    h = rng.uniform(1.0, 3.0, 2)
    return np.array([c - h, [c[0] + h[0], c[1] - h[1]], c + h, [c[0] - h[0], c[1] + h[1]]])


def repair_runs(base: Problem, repairs: int, nodes: int, cap_s: float) -> list[dict]:
    cfg = RRTXConfig(goal=tuple(base.goal), bounds=base.bounds, robot_radius=RADIUS)
    planner = RRTX(cfg, np.random.default_rng(7))
    for i, poly in enumerate(base.grown):
        planner.add_obstacle(f'o{i}', poly)
    planner.set_robot(base.start)
    while planner.node_count < nodes:
        planner.run(CHUNK)
    rng = np.random.default_rng(11)
    out = []
    for k in range(repairs):
        box = box_across(planner.path(), rng)
        if not all(vo.clearance(np.array([p]), [box]) > 2 * RADIUS for p in (base.start,
                                                                              base.goal)):
            continue
        grown_box = grow([box], RADIUS)[0]
        before = planner.cost()
        t0 = time.perf_counter()
        planner.add_obstacle('appeared', grown_box)
        repair_s = time.perf_counter() - t0
        after = planner.cost()
        path = planner.path()
        polys = list(base.polygons) + [box]
        problem = make_problem('repair', polys, base.start, base.goal)
        row = {'before': before, 'after': after, 'repair_ms': 1e3 * repair_s,
               'optimum': problem.optimum, 'nodes': planner.node_count,
               'clear': bool(len(path) and vo.clearance(path, polys) >= RADIUS)}
        if math.isfinite(after):
            query = OmplQuery(problem.grown, base.start, base.goal, base.bounds)
            for name in PLANNERS:
                row[name] = query.time_to_cost(name, after, cap_s)
        out.append(row)
        print(f'  repair {k}: {row["repair_ms"]:.1f} ms, cost {before:.2f} -> {after:.2f} '
              f'(opt {problem.optimum:.2f}); OMPL to same cost: '
              + ', '.join(f"{n} {row[n]['time_s'] if row[n]['reached'] else 'no'}"
                          for n in PLANNERS if n in row), flush=True)
        planner.remove_obstacle('appeared')
        planner.run(50)
    return out


def repair_table(rows: list[dict], cap_s: float) -> tuple[str, dict]:
    ms = np.array([r['repair_ms'] for r in rows])
    lines = [f'\n**Repair** (rand_Static, node configuration δ = 5 m, ~{rows[0]["nodes"]} nodes, '
             f'{len(rows)} boxes of half-size 1–3 m appearing across the current path)\n',
             f'RRT^X repair (add_obstacle, wall): median {np.median(ms):.1f} ms, '
             f'p95 {np.percentile(ms, 95):.1f} ms, max {ms.max():.1f} ms; repaired paths '
             f'collision-free: {sum(r["clear"] for r in rows)}/{len(rows)}; repaired cost / '
             f'optimum: median {np.median([r["after"] / r["optimum"] for r in rows]):.4f}.\n',
             '| OMPL from scratch | reached the repaired cost | median time (s) | '
             'median ratio to RRT^X repair | median time to first solution (s) |',
             '|---|---|---|---|---|']
    summary = {'repair_ms': {'median': float(np.median(ms)),
                             'p95': float(np.percentile(ms, 95)), 'max': float(ms.max())}}
    for name in PLANNERS:
        got = [r for r in rows if name in r]
        reached = [r for r in got if r[name]['reached']]
        times = [r[name]['time_s'] for r in reached]
        ratio = [r[name]['time_s'] / (r['repair_ms'] / 1e3) for r in reached]
        first = [r[name]['first_s'] for r in got if r[name]['first_s'] is not None]
        summary[name] = {'reached': len(reached), 'of': len(got),
                         'median_s': _median(times), 'median_ratio': _median(ratio)}
        med_t, med_r, med_f = _median(times), _median(ratio), _median(first)
        lines.append(f'| {name} | {len(reached)}/{len(got)} (cap {cap_s:g} s) | '
                     f"{f'{med_t:.3f}' if math.isfinite(med_t) else '—'} | "
                     f"{f'{med_r:.0f}×' if math.isfinite(med_r) else '—'} | "
                     f"{f'{med_f:.3f}' if math.isfinite(med_f) else '—'} |")
    return '\n'.join(lines), summary


def iteration_times(base: Problem, sizes: list[int]) -> list[dict]:
    cfg = RRTXConfig(goal=tuple(base.goal), bounds=base.bounds, robot_radius=RADIUS)
    planner = RRTX(cfg, np.random.default_rng(3))
    for i, poly in enumerate(base.grown):
        planner.add_obstacle(f'o{i}', poly)
    planner.set_robot(base.start)
    out = []
    for n in sizes:
        while planner.node_count < 0.95 * n:
            planner.run(CHUNK)
        blocks = []
        while planner.node_count < 1.05 * n:
            c0 = time.process_time()
            planner.run(100)
            blocks.append((time.process_time() - c0) / 100)
        us = 1e6 * float(np.median(blocks))
        out.append({'n': n, 'us_per_iteration': us, 'iterations_per_s': 1e6 / us,
                    'radius': planner.radius})
        print(f'  n ~{n}: {us:.0f} µs/iteration', flush=True)
    return out


def iteration_table(rows: list[dict]) -> str:
    base = rows[0]
    lines = ['\n**Iteration time against n** (rand_Static, δ = 5 m, median of 100-iteration '
             'blocks between 0.95 n and 1.05 n, CPU time)\n',
             '| n | µs / iteration | iterations / s | r(n) (m) | time ratio to n = '
             f'{base["n"]} | log n ratio |', '|---|---|---|---|---|---|']
    for r in rows:
        lines.append(f'| {r["n"]} | {r["us_per_iteration"]:.0f} | {r["iterations_per_s"]:.0f} '
                     f'| {r["radius"]:.2f} | {r["us_per_iteration"] / base["us_per_iteration"]:.2f} '
                     f'| {math.log(r["n"]) / math.log(base["n"]):.2f} |')
    return '\n'.join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='one seed, fewer repairs (smoke test)')
    args = ap.parse_args()
    load0 = os.getloadavg()
    t_start = time.perf_counter()
    forest_seeds = [1000, 1001, 1002, 1003, 1004] if not args.quick else [1000]
    seeds = [0, 1, 2, 3, 4] if not args.quick else [0]
    probs = problems(forest_seeds)
    print('costs', flush=True)
    runs = cost_runs(probs, {'BNeck': seeds, 'rand_Static': seeds})
    cost_md, cost_summary = cost_table(runs)
    print('repairs', flush=True)
    cap = 5.0
    repairs = repair_runs(probs[1], 10 if not args.quick else 2, 3000, cap)
    repair_md, repair_summary = repair_table(repairs, cap)
    print('iteration time', flush=True)
    sizes = [500, 1000, 2000, 4000, 8000, 16000] if not args.quick else [500, 1000]
    iters = iteration_times(probs[1], sizes)
    load1 = os.getloadavg()
    header = (f'Robot radius {RADIUS} m; OMPL {metadata.version("ompl")} (the wheel); forests: '
              f'seeds {forest_seeds} (one planner seed each); BNeck and rand_Static: planner '
              f'seeds {seeds}.  Budgets are wall time on a shared machine (load average '
              f'{load0[0]:.1f} at the start, {load1[0]:.1f} at the end); the whole run took '
              f'{(time.perf_counter() - t_start) / 60:.1f} min.\n')
    table = header + cost_md + '\n' + repair_md + '\n' + iteration_table(iters)
    save('planner_vs_ompl' if not args.quick else 'planner_vs_ompl_quick',
         {'checkpoints_s': list(CHECKPOINTS), 'load_average': [load0[0], load1[0]],
          'summary': {'cost': cost_summary, 'repair': repair_summary}, 'cost_runs': runs,
          'repairs': repairs, 'iteration_time': iters}, table)
    sys.stdout.flush()
    os._exit(0)  # the OMPL bindings report leaked instances at interpreter exit


if __name__ == '__main__':
    main()
