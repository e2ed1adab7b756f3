#!/usr/bin/env python3
"""Per-step cost of the margin policies (issue 11: <= 2 ms median per step).

A stream of safety-side samples is recorded once from the true plant (the rover without a
spring, a PD law with decaying probing, 3.5 m legs between random points of the 40 x 40 m
square, a field bump), then replayed through each policy; only ``policy.step`` is timed.
Reported: median, p95, max per step, and the median of the steps at which a leg starts
(learned_bound fits the model and the field and builds the tube there). Usage::

    python benchmarks/margin_step.py [--steps 6000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import save  # noqa: E402
from rrtq_controller.legs import LegSequencer  # noqa: E402
from rrtq_planner.margins.build import make_policy  # noqa: E402
from rrtq_planner.margins.policy import LegInfo, MarginMode, MarginSample  # noqa: E402
from rrtq_sim.field import Bump, DisturbanceField, compose_input_matrix  # noqa: E402
from rrtq_sim.plant import Plant, rover_matrices  # noqa: E402

DT = 0.05
REGION = ((-20.0, 20.0), (-20.0, 20.0))
PD = np.array([[40.0, 0.0, 30.0, 0.0], [0.0, 40.0, 0.0, 30.0]])


def samples(steps: int, seed: int = 0) -> list[MarginSample]:
    a_mat, b_mat = rover_matrices(40.0, 0.0, 45.0)
    plant = Plant(a_mat, b_mat, compose_input_matrix(None, 4), DT, 1000.0)
    field = DisturbanceField([Bump((0.0, 0.0), 6.0, (0.2, -0.1))])
    rng = np.random.default_rng(seed)
    probe = 20.0 * lfilter([0.22], [1.0, -0.975], rng.standard_normal((steps, 2)), axis=0)
    points = rng.uniform(-16, 16, (40, 2))
    route = []
    last = np.array([-15.0, -15.0])
    for p in points:
        k = int(np.ceil(np.linalg.norm(p - last) / 3.5))
        route += [last + (p - last) * i / k for i in range(1, k + 1)]
        last = p
    legs = LegSequencer(rho=0.1, horizon=10.0)
    x = np.array([-15.0, -15.0, 0.0, 0.0])
    legs.set_plan(np.array(route), x, 0.0)
    out, prev = [], None
    gain = lambda tau: PD  # noqa: E731
    for k in range(steps):
        t = k * DT
        out.append(MarginSample(t, x) if prev is None else MarginSample(t, x, *prev, gain, 10.0))
        legs.update(x, t)
        leg = legs.leg
        p = probe[k] * 0.85 ** leg.index
        u = -PD @ (x - leg.target) + p
        prev = (LegInfo(leg.index, leg.x0[:2].copy(), leg.target[:2].copy(), leg.d0), u, p)
        x = plant.step(x, u, field.acceleration(x), np.zeros(2))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--steps', type=int, default=6000)
    ap.add_argument('--repeat', type=int, default=3)
    args = ap.parse_args()
    stream = samples(args.steps)
    starts = np.flatnonzero(np.diff([s.leg.index if s.leg else -1 for s in stream]) != 0) + 1
    results = {'steps': args.steps, 'legs': int(len(starts)), 'modes': {}}
    lines = [f'{args.steps} steps ({args.steps * DT:.0f} s simulated, {len(starts)} legs), '
             f'each replayed {args.repeat}x through the policy; ms per step.', '',
             '| mode | median | p95 | max | median at leg starts |', '|---|---|---|---|---|']
    for mode in MarginMode:
        times = []
        for _ in range(args.repeat):
            policy = make_policy(mode, region=REGION, dt=DT)
            run = np.zeros(len(stream))
            for i, s in enumerate(stream):
                t0 = time.perf_counter()
                policy.step(s)
                run[i] = time.perf_counter() - t0
            times.append(run)
        ms = 1e3 * np.median(np.array(times), axis=0)       # per step, median over repeats
        row = {'median': float(np.median(ms)), 'p95': float(np.percentile(ms, 95)),
               'max': float(ms.max()), 'leg_start_median': float(np.median(ms[starts]))}
        results['modes'][mode.value] = row
        lines.append(f"| {mode.value} | {row['median']:.3f} | {row['p95']:.3f} | "
                     f"{row['max']:.1f} | {row['leg_start_median']:.1f} |")
    save('margin_step', results, '\n'.join(lines))


if __name__ == '__main__':
    main()
