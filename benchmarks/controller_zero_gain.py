#!/usr/bin/env python3
"""The least-squares controller from a zero initial gain on the rover without a spring.

Same problem as ``controller_bench.py`` (stiffness 0, M = 10 I, R = 0.02 I, P(T) = 0.5 I,
T = 10 s, Δt = 0.05 s, ρ = 0.15, 20 legs of 3-8 m in random directions on a true plant the
controller never sees) but without ``initial_gain``: the zero policy leaves the robot where
it is until the controller widens its time basis (after two legs that run out of horizon)
and improves on it. Per seed: the leg at which the basis was widened, the gain error at
legs 10 and 20, the median and max leg cost / optimum over legs 11-20, and whether legs
11-20 all reached their window.

Usage: ``.venv/bin/python benchmarks/controller_zero_gain.py [--seeds 0 1 2 3 4 5]``;
writes ``benchmarks/results/controller_zero_gain.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import save  # noqa: E402
from rrtq_testing import controller_reference  # noqa: E402

from rrtq_controller.config import ControllerConfig  # noqa: E402
from rrtq_controller.q_learning import QLearningController  # noqa: E402

LEGS = 20


def run(seed: int, ref) -> dict:
    cfg = ControllerConfig(M=10.0, R=0.02, P_T=0.5, probing_std=20.0)
    A, B = ref.rover(stiffness=0.0)
    ctrl = QLearningController(cfg, 4, 2, 0, np.random.default_rng(seed))
    widened_at: list[int] = []
    start_leg = ctrl.start_leg

    def watched(x0, t):
        start_leg(x0, t)
        if ctrl.widened and not widened_at:
            widened_at.append(ctrl.leg_index)
    ctrl.start_leg = watched  # type: ignore[method-assign]
    recs = ref.run_legs(ctrl, A, B, 10.0 * np.eye(4), 0.02 * np.eye(2), 0.5 * np.eye(4),
                        cfg.horizon, cfg.dt, ref.random_legs(np.random.default_rng(seed + 1000), LEGS),
                        cfg.rho)
    ratios = [r.cost_ratio for r in recs[10:]]
    return {'seed': seed, 'widened_at_leg': widened_at[0] if widened_at else None,
            'gain_error_leg10': recs[9].gain_error, 'gain_error_leg20': recs[-1].gain_error,
            'median_ratio_11_20': float(np.median(ratios)), 'max_ratio_11_20': float(max(ratios)),
            'reached_11_20': all(r.reached for r in recs[10:])}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2, 3, 4, 5])
    args = ap.parse_args()
    ref = controller_reference
    rows = []
    for seed in args.seeds:
        rows.append(run(seed, ref))
        print(rows[-1], file=sys.stderr, flush=True)
    lines = ['Rover without a spring, no initial gain, 20 legs of 3-8 m per seed.', '',
             '| seed | basis widened at leg | gain error leg 10 / 20 | '
             'cost/optimum legs 11-20 median / max | legs 11-20 in window |',
             '|---|---|---|---|---|']
    for r in rows:
        lines.append(f"| {r['seed']} | {r['widened_at_leg']} | {r['gain_error_leg10']:.3f} / "
                     f"{r['gain_error_leg20']:.3f} | {r['median_ratio_11_20']:.4f} / "
                     f"{r['max_ratio_11_20']:.3f} | {r['reached_11_20']} |")
    save('controller_zero_gain', {'legs': LEGS, 'runs': rows}, '\n'.join(lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
