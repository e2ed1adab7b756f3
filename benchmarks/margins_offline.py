#!/usr/bin/env python3
"""Offline study of the safety margins (issue 11): running_max vs conformal vs learned_bound.

No ROS: the true plant (``rrtq_sim.plant.Plant``, exact ZOH) with a position-dependent field
(a gust bump at the start, a weaker bump mid-way), driven leg by leg by the Q-learning
controller (``LearningDriver``) along a route of 3.5 m legs between random points of the
40 x 40 m square; the margin policies only watch (they feed nothing back: the route is
fixed), so all modes see the same legs. The rover without a spring and the controller of
``scenarios/rover_no_spring.yaml`` (the controller does all the work; probing 20 N decaying
0.85 per leg: the learning transient).

Each seed runs two missions from the same start with a fresh controller; in the second the
conformal policies start from the first mission's scores (the calibration file a run
writes). Per leg the margin in force at its start is checked against its largest deviation.
Also measured: per-segment scores (4 per leg) used as calibration for leg maxima (are finer
scores valid?), and the one-step model's error fitted jointly with the field vs by recursive
least squares alone (two-stage). Usage::

    python benchmarks/margins_offline.py [--seeds 6] [--out benchmarks/results]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import RESULTS, save  # noqa: E402
from rrtq_controller.config import ControllerConfig  # noqa: E402
from rrtq_controller.driver import LearningDriver  # noqa: E402
from rrtq_planner.margins.calibration import Calibration  # noqa: E402
from rrtq_planner.margins.conformal import ConformalConfig, conformal_quantile  # noqa: E402
from rrtq_planner.margins.coverage import binomial_interval  # noqa: E402
from rrtq_planner.margins.learned import LearnedBoundConfig, LearnedBoundPolicy  # noqa: E402
from rrtq_planner.margins.observer import OneStepModel  # noqa: E402
from rrtq_planner.margins.policy import (ConformalPolicy, LegInfo, MarginSample,  # noqa: E402
                                         RunningMaxPolicy)
from rrtq_sim.field import Bump, DisturbanceField, compose_input_matrix  # noqa: E402
from rrtq_sim.plant import Plant, rover_matrices  # noqa: E402

DT = 0.05
FORCE_LIMIT = 1000.0
REGION = ((-20.0, 20.0), (-20.0, 20.0))
START = np.array([-15.0, -15.0])
FIELD = [Bump((-14.0, -13.0), 4.0, (0.25, -0.2)),      # a gust where the robot starts
         Bump((0.0, 2.0), 6.0, (-0.15, 0.1))]
CONTROLLER = ControllerConfig(M=10.0, R=0.02, P_T=0.5, rho=0.1, horizon=10.0, dt=DT,
                              initial_gain=((40.0, 0.0, 30.0, 0.0), (0.0, 40.0, 0.0, 30.0)),
                              probing_std=20.0, probing_decay=0.85)
SEGMENTS = 4
DELTA = 0.05
MODES = ('running_max', 'conformal_plain', 'conformal_adaptive', 'learned_bound')


def route(rng: np.random.Generator, points: int = 7, step: float = 3.5) -> np.ndarray:
    """Waypoints at most ``step`` apart through ``points`` random points of the square."""
    out = [START]
    for p in rng.uniform(-16.0, 16.0, (points, 2)):
        a = out[-1]
        k = max(int(math.ceil(np.linalg.norm(p - a) / step)), 1)
        out += [a + (p - a) * (i / k) for i in range(1, k + 1)]
    return np.array(out[1:])


def policies(calibration: list[float]) -> dict:
    return {
        'running_max': RunningMaxPolicy(),
        'conformal_plain': ConformalPolicy(ConformalConfig(adaptation=0.0),
                                           calibration=calibration),
        'conformal_adaptive': ConformalPolicy(ConformalConfig(), calibration=calibration),
        'learned_bound': LearnedBoundPolicy(LearnedBoundConfig(region=REGION, dt=DT)),
    }


def mission(seed: int, waypoints: np.ndarray, calibration: list[float], duration: float = 400.0):
    a_mat, b_mat = rover_matrices(40.0, 0.0, 45.0)
    plant = Plant(a_mat, b_mat, compose_input_matrix(None, 4), DT, FORCE_LIMIT)
    field = DisturbanceField(FIELD)
    driver = LearningDriver(CONTROLLER, 4, 2, 0, np.random.default_rng(seed))
    pols = policies(calibration)
    x = np.concatenate([START, np.zeros(2)])
    driver.set_plan(waypoints, x, 0.0)
    rls = OneStepModel(4, 2)
    trace = {name: [] for name in pols}
    cost = {name: [] for name in pols}
    d_rob, leg_of, times = [], [], []
    out = None
    for k in range(int(duration / DT)):
        t = k * DT
        sample = MarginSample(t, x) if out is None else MarginSample(
            t, x, LegInfo(out.leg_index, out.leg_start, out.leg_target, out.d0), out.u,
            out.probing, driver.controller.gain, CONTROLLER.horizon)
        for name, pol in pols.items():
            t0 = time.perf_counter()
            status = pol.step(sample)
            cost[name].append(time.perf_counter() - t0)
            trace[name].append((status.margin, status.leg_margin))
        d_rob.append(pols['running_max'].legs.d_rob)
        leg_of.append(out.leg_index if out is not None else -1)
        times.append(t)
        x_prev = x
        out = driver.step(t, x)
        # The controller is to command no more than the actuator's limit (docs/design.md,
        # contract additions: controller.force_limit, coming); the study applies it here.
        out = dataclasses.replace(out, u=np.clip(out.u, -FORCE_LIMIT, FORCE_LIMIT))
        x = plant.step(x, out.u, field.acceleration(x), out.leg_target)
        xr = np.concatenate([out.leg_target, np.zeros(2)])
        rls.update(rls.regressor(x_prev - xr, out.u), x - xr)
        if driver.legs.goal_reached:
            break
    learned = pols['learned_bound']
    return {'trace': {n: np.array(v) for n, v in trace.items()}, 'd_rob': np.array(d_rob),
            'leg': np.array(leg_of), 't': np.array(times), 'cost': cost,
            'reached': bool(driver.legs.goal_reached),
            'phi_error_joint': float(np.abs(learned.theta[:, :4] - plant.phi).max()),
            'phi_error_rls': float(np.abs(rls.phi - plant.phi).max())}


def legs_of(run: dict) -> list[dict]:
    """Per finished leg: score, segment scores, and each mode's margin at its start."""
    leg, d = run['leg'], run['d_rob']
    out = []
    indices = [i for i in np.unique(leg) if i >= 0]
    for i in indices[:-1]:                       # the last leg is still running at the end
        sel = np.flatnonzero(leg == i)
        seg = [float(d[s].max()) for s in np.array_split(sel, SEGMENTS) if len(s)]
        out.append({'score': float(d[sel].max()), 'segments': seg,
                    'margin': {n: float(v[sel[0], 1]) for n, v in run['trace'].items()}})
    return out


def segment_coverage(calibration_segments: list[float], legs: list[dict], window: int = 200):
    """Conformal on per-segment scores (window of segments) predicting each leg's maximum."""
    pool = list(calibration_segments)
    hits, margins = [], []
    for leg in legs:
        q = conformal_quantile(np.array(pool[-window:]), DELTA)
        if math.isfinite(q):
            hits.append(leg['score'] <= q)
            margins.append(q)
        pool += leg['segments']
    return hits, margins


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=6)
    ap.add_argument('--out', type=Path, default=RESULTS)
    args = ap.parse_args()
    rows = {n: {'legs': 0, 'misses': 0, 'margin': [], 'score': []} for n in MODES}
    rows2 = {n: {'legs': 0, 'misses': 0, 'margin': [], 'score': []} for n in MODES}
    seg_hits, seg_margin, leg_hits = [], [], []
    costs = {n: [] for n in MODES}
    phi_err = {'joint': [], 'rls': []}
    reached = 0
    example = None
    for seed in range(args.seeds):
        waypoints = route(np.random.default_rng(1000 + seed))
        first = mission(seed, waypoints, [])
        legs1 = legs_of(first)
        second = mission(seed + 500, waypoints, [leg['score'] for leg in legs1])
        legs2 = legs_of(second)
        calib = Calibration(tuple(leg['score'] for leg in legs1), f'offline seed {seed}')
        assert len(calib.scores) == len(legs1)
        if example is None:
            example = (first, legs1, second, legs2)
        for run, legs, table in ((first, legs1, rows), (second, legs2, rows2)):
            reached += run['reached']
            for leg in legs:
                for n in MODES:
                    m = leg['margin'][n]
                    table[n]['legs'] += 1
                    table[n]['misses'] += leg['score'] > m
                    table[n]['margin'].append(m)
                    table[n]['score'].append(leg['score'])
            for n in MODES:
                costs[n] += run['cost'][n]
            phi_err['joint'].append(run['phi_error_joint'])
            phi_err['rls'].append(run['phi_error_rls'])
        hits, margins = segment_coverage([s for leg in legs1 for s in leg['segments']], legs2)
        seg_hits += hits
        seg_margin += margins
        leg_hits += [leg['score'] <= leg['margin']['conformal_plain'] for leg in legs2]
        print(f'seed {seed}: {len(legs1)} + {len(legs2)} legs, reached {first["reached"]}, '
              f'{second["reached"]}', flush=True)
    table = render(rows, rows2, seg_hits, seg_margin, leg_hits, costs, phi_err, reached,
                   2 * args.seeds)
    results = {
        'first_mission': {n: summary(r) for n, r in rows.items()},
        'second_mission_calibrated': {n: summary(r) for n, r in rows2.items()},
        'segment_scores': {'legs': len(seg_hits), 'covered': int(sum(seg_hits)),
                           'mean_margin': float(np.mean(seg_margin)) if seg_margin else None},
        'step_ms': {n: {'median': 1e3 * float(np.median(c)), 'p95': 1e3 * float(np.percentile(c, 95))}
                    for n, c in costs.items()},
        'phi_error': {k: float(np.median(v)) for k, v in phi_err.items()},
        'missions_reached': reached, 'missions': 2 * args.seeds,
    }
    figure(example, args.out / 'margins_offline.png')
    save('margins_offline', results, table + '\n\n![margins](margins_offline.png)')


def summary(r: dict) -> dict:
    low, high = binomial_interval(r['legs'] - r['misses'], r['legs'])
    return {'legs': r['legs'], 'violations': r['misses'], 'coverage': 1 - r['misses'] / r['legs'],
            'coverage_interval': [low, high],
            'mean_margin_m': float(np.mean([m for m in r['margin'] if math.isfinite(m)]))}


def render(rows, rows2, seg_hits, seg_margin, leg_hits, costs, phi_err, reached, missions) -> str:
    lines = [f'{missions // 2} seeds x 2 missions of the rover without a spring (Q-learning '
             f'controller, probing 20 N decaying 0.85/leg) along 3.5 m legs through a field '
             f'(gust bump 0.32 m/s² at the start, 0.18 m/s² mid-way); {reached}/{missions} '
             f'missions reached the route\'s end (400 s each). In the second mission only the '
             f'conformal modes start from the first mission\'s scores. Coverage = legs whose largest deviation '
             f'stayed within the margin in force at their start (1 − δ = 0.95; 95 % '
             f'Clopper-Pearson interval).', '',
             '| mode | mission | legs | violations | coverage [interval] | mean margin (m) | '
             'mean deviation (m) | step ms median / p95 |', '|---|---|---|---|---|---|---|---|']
    for n in MODES:
        for label, table in (('first', rows), ('second, calibrated', rows2)):
            s = summary(table[n])
            mean_score = np.mean(table[n]['score'])
            c = costs[n]
            lines.append(
                f"| {n} | {label} | {s['legs']} | {s['violations']} | {s['coverage']:.3f} "
                f"[{s['coverage_interval'][0]:.3f}, {s['coverage_interval'][1]:.3f}] | "
                f"{s['mean_margin_m']:.3f} | {mean_score:.3f} | "
                f"{1e3 * np.median(c):.3f} / {1e3 * np.percentile(c, 95):.2f} |")
    if seg_hits:
        low, high = binomial_interval(int(sum(seg_hits)), len(seg_hits))
        lines += ['', f'Per-segment scores ({SEGMENTS} per leg) as calibration for the second '
                  f'missions\' leg maxima: coverage {np.mean(seg_hits):.3f} [{low:.3f}, '
                  f'{high:.3f}] over {len(seg_hits)} legs, mean margin '
                  f'{np.mean(seg_margin):.3f} m (leg scores: coverage '
                  f'{np.mean(leg_hits):.3f}).']
    lines += ['', f"One-step model error max|Φ̂ − Φ| (median over missions): fitted jointly "
              f"with the field {np.median(phi_err['joint']):.2e}, recursive least squares alone "
              f"{np.median(phi_err['rls']):.2e}."]
    return '\n'.join(lines)


def figure(example, path: Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharey=True)
    for ax, (run, _legs, title) in zip(axes, ((example[0], example[1], 'first mission'),
                                             (example[2], example[3],
                                              'second mission, conformal calibrated by the first'))):
        ax.plot(run['t'], run['d_rob'], color='0.6', lw=0.8, label='D_rob (realised)')
        for n, style in zip(MODES, ('k-', 'C0--', 'C1-', 'C2-')):
            ax.plot(run['t'], run['trace'][n][:, 0], style, lw=1.2, label=n)
        ax.set_yscale('log')
        ax.set_ylim(1e-3, 20)
        ax.set_title(title)
        ax.set_ylabel('m')
        ax.grid(True, which='both', alpha=0.3)
    axes[-1].set_xlabel('simulated time (s)')
    axes[0].legend(loc='upper right', fontsize=8, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == '__main__':
    main()
