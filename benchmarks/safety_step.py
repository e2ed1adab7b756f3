#!/usr/bin/env python3
"""Per-step cost of the safety monitor, with and without the obstacle ahead.

The safety node's core (:class:`rrtq_planner.safety.SafetyMonitor`, ``look_ahead`` 0: the
step without the obstacle ahead) steps a robot along the diagonal of
``scenarios/forest_100.yaml`` at 1 m/s, weaving 0.3 m about it, with every one of its trees
farther than 1.5 m from the diagonal detected (the worst case: in a run only the perceived
ones are), legs of 5 m as the
planner steers them. At the same steps the obstacle ahead is cast on its own
(:func:`rrtq_planner.safety.obstacle_ahead`: the robot's disc along its velocity, which swings
±46° about the diagonal, 5 m, against
the detected obstacles grown by its radius), as ``step`` does it with the default
``look_ahead``. Both are timed; the issue's budget for the whole safety step is 2 ms
(median). The steps that republish the augmented set (the margin grew by the growth
threshold: every tree grown again) are reported apart.

A second pass detects the trees as the robot comes within ``PERCEPTION`` of them, as the
spawner does, so the map grows one tree at a time: each change republishes the augmented set.
It runs twice, side by side: as the monitor is (an obstacle unchanged since the last
publication, by the same radius, is reused: :class:`rrtq_planner.safety.GrownCache`) and with
every obstacle grown afresh at each change, as before. Usage::

    python benchmarks/safety_step.py [--steps 2000]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import shapely

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import ROOT, save  # noqa: E402
from rrtq_common.lockstep import OnChange  # noqa: E402
from rrtq_common.world_yaml import load_world  # noqa: E402
from rrtq_planner.safety import (  # noqa: E402
    GrownCache, Leg, SafetyConfig, SafetyMonitor, obstacle_ahead)

DT = 0.05
SPEED = 1.0          # m/s
LEG = 5.0            # m
CLEAR = 1.5          # m: trees nearer the diagonal are left out
PERCEPTION = 8.0     # m: the second pass detects a tree within this of the robot


class Afresh(GrownCache):
    """Grows every obstacle again at each call (the monitor before the reuse)."""

    def grow(self, items):
        self._last = {}
        return super().grow(items)


def path_point(start: np.ndarray, heading: np.ndarray, k: int) -> tuple[np.ndarray, Leg]:
    s = SPEED * DT * k
    p = start + s * heading + 0.3 * math.sin(0.2 * s) * np.array([-heading[1], heading[0]])
    index = int(s // LEG)
    return p, Leg(index, tuple(start + index * LEG * heading),
                  tuple(start + (index + 1) * LEG * heading), LEG)


def perceived_pass(trees, start, heading, steps: int, afresh: bool) -> tuple[list[float], int, int]:
    """Times (ms) of the steps whose detected set changed; the changes; obstacles grown afresh."""
    monitor = SafetyMonitor(SafetyConfig(robot_radius=0.5, look_ahead=0.0))
    if afresh:
        monitor._grown_swept, monitor._grown_augmented = Afresh(), Afresh()
    seen: list = []
    detected, times = None, []
    for k in range(steps + 1):
        p, leg = path_point(start, heading, k)
        new = [t for t in trees if t not in seen
               and shapely.Polygon(t[1]).distance(shapely.Point(p)) <= PERCEPTION]
        if new:
            seen = seen + new
            detected = OnChange(k, lambda now=tuple(seen): list(now))
        t0 = time.perf_counter()
        monitor.step(k * 50_000_000, p, detected, leg)
        if new and k:
            times.append(1e3 * (time.perf_counter() - t0))
    return times, len(times), monitor.grown


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--steps', type=int, default=2000)
    args = ap.parse_args()
    world = load_world(ROOT / 'scenarios/forest_100.yaml')
    start, goal = np.asarray(world.start, dtype=float), np.asarray(world.goal, dtype=float)
    heading = (goal - start) / np.linalg.norm(goal - start)
    # the trees the weave would run into are not there (a plan goes around them)
    trees = [(spec.id, np.asarray(spec.polygon, dtype=float)) for spec in world.obstacles
             if shapely.LineString([start, goal]).distance(shapely.Polygon(spec.polygon)) > CLEAR]
    detected = OnChange(0, lambda: trees)
    monitor = SafetyMonitor(SafetyConfig(robot_radius=world.robot_radius, look_ahead=0.0))
    steps, republish, cast, met = [], [], [], 0
    for k in range(args.steps + 1):
        s = SPEED * DT * k
        p, leg = path_point(start, heading, k)
        t0 = time.perf_counter()
        out = monitor.step(k * 50_000_000, p, detected, leg)
        turn = 0.8 * math.sin(0.15 * s)   # rad: the velocity swings across the trees beside
        c, n = math.cos(turn), math.sin(turn)
        velocity = SPEED * np.array([c * heading[0] - n * heading[1], n * heading[0] + c * heading[1]])
        t1 = time.perf_counter()
        distance, _ = obstacle_ahead(p, velocity, monitor.swept, 5.0)
        t2 = time.perf_counter()
        if k:                           # the first step grows every tree
            (steps if out.augmented is None else republish).append(1e3 * (t1 - t0))
            cast.append(1e3 * (t2 - t1))
            met += math.isfinite(distance)

    def stats(v: list[float]) -> dict:
        a = np.asarray(v)
        return {'steps': len(a), 'median': float(np.median(a)), 'p95': float(np.percentile(a, 95)),
                'max': float(a.max())}
    rows = {'step, no look-ahead': stats(steps), 'step that republishes': stats(republish),
            'obstacle ahead (the cast)': stats(cast)}
    reused, changes, grown_reused = perceived_pass(trees, start, heading, args.steps, False)
    fresh, _, grown_fresh = perceived_pass(trees, start, heading, args.steps, True)
    rows['map grew by perception, reusing'] = stats(reused)
    rows['map grew by perception, all afresh'] = stats(fresh)
    speedup = float(np.sum(fresh) / np.sum(reused))
    share = rows['obstacle ahead (the cast)']['median'] / rows['step, no look-ahead']['median']
    lines = [f'{args.steps} steps along the diagonal of forest_100 ({len(trees)} trees, all detected); ms. '
             f'An obstacle within 5 m ahead on {met} of the steps.', '',
             '| what | steps | median | p95 | max |', '|---|---|---|---|---|']
    lines += [f"| {name} | {r['steps']} | {r['median']:.3f} | {r['p95']:.3f} | {r['max']:.2f} |"
              for name, r in rows.items()]
    lines += ['', f'The cast adds {share:.2f} x the median step without it; the step with it: '
              f"{rows['step, no look-ahead']['median'] + rows['obstacle ahead (the cast)']['median']:.2f} ms "
              'median (budget 2 ms).']
    lines += ['', f'The map grown by perception ({PERCEPTION:g} m): {changes} changes of the '
              f'detected set, each republishing; {grown_reused} obstacles grown with reuse '
              f'against {grown_fresh} afresh; those steps take {speedup:.1f} x less time in '
              'all with reuse (same run, side by side).']
    save('safety_step', {'steps': args.steps, 'trees': len(trees), 'ahead_steps': met, 'ms': rows,
                         'cast_over_step': share, 'detection_changes': changes,
                         'grown_reused': grown_reused, 'grown_afresh': grown_fresh,
                         'detection_steps_speedup': speedup}, '\n'.join(lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
