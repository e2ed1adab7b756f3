#!/usr/bin/env python3
"""Quick measurement of the Q-learning controller core against the Riccati optimum.

For each critic law (the papers' normalised gradient and the least-squares critic) the
controller drives a sequence of random legs of 3-8 m (velocity carried across waypoint
switches) on a true plant it never sees; per leg it prints the gain error
mean_τ ‖K̂(τ) - R⁻¹BᵀP(τ)‖ / ‖R⁻¹BᵀP(τ)‖ and the leg cost (running cost plus optimal
cost-to-go from where the leg ended) over the optimum ½ x̄0ᵀ P(T) x̄0, and the per-step
compute time (median, p99). Usage::

    .venv/bin/python benchmarks/controller_quick.py [--legs 20] [--plant nospring|paper]
        [--seed 0] [--law gradient|least_squares]... [--actor whitened|gradient]
        [--json benchmarks/results/controller_quick.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from rrtq_controller.config import ActorLaw, ControllerConfig, CriticLaw
from rrtq_controller.q_learning import QLearningController
from common import time_steps
from rrtq_testing import controller_reference


PLANTS = {
    # name: (stiffness N/m, M, R, initial PD gain (N/m, N s/m))
    'nospring': (0.0, 10.0, 0.02, (40.0, 30.0)),
    'paper': (20.0, 10.0, 2.0, None),
}


def config_for(plant: str, law: CriticLaw, actor: ActorLaw = ActorLaw.WHITENED) -> ControllerConfig:
    _, M, R, pd = PLANTS[plant]
    k0 = None if pd is None else ((pd[0], 0.0, pd[1], 0.0), (0.0, pd[0], 0.0, pd[1]))
    std = 20.0 if plant == 'nospring' else 2.0  # N: forces of the two plants differ 100x
    return ControllerConfig(M=M, R=R, P_T=0.5, critic_law=law, actor_law=actor, initial_gain=k0, probing_std=std)


def run(plant: str, law: CriticLaw, legs: int, seed: int, ref, actor: ActorLaw = ActorLaw.WHITENED) -> dict:
    k, M, R, _ = PLANTS[plant]
    A, B = ref.rover(stiffness=k)
    cfg = config_for(plant, law, actor)
    ctrl = QLearningController(cfg, 4, 2, 0, np.random.default_rng(seed))
    times = time_steps(ctrl)
    diverged = None
    try:
        records = ref.run_legs(ctrl, A, B, M * np.eye(4), R * np.eye(2), 0.5 * np.eye(4), cfg.horizon, cfg.dt,
                               ref.random_legs(np.random.default_rng(seed + 1000), legs), cfg.rho)
    except ref.Diverged as exc:
        records, diverged = exc.records, str(exc)
    ms = 1e3 * np.asarray(times)
    return {
        'plant': plant, 'law': law.value, 'actor': actor.value, 'seed': seed, 'warnings': ctrl.check_gains(),
        'legs': [{'D0': float(np.linalg.norm(r.x0)), 'steps': r.steps, 'reached': r.reached,
                  'gain_error': r.gain_error, 'cost_ratio': r.cost_ratio} for r in records],
        'diverged': diverged,
        'step_ms': {'median': float(np.median(ms)), 'p99': float(np.percentile(ms, 99))},
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--legs', type=int, default=20)
    ap.add_argument('--plant', choices=sorted(PLANTS), default='nospring')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--law', choices=[c.value for c in CriticLaw], action='append')
    ap.add_argument('--actor', choices=[a.value for a in ActorLaw], default=ActorLaw.WHITENED.value)
    ap.add_argument('--json', type=Path)
    args = ap.parse_args()
    ref = controller_reference
    results = []
    for law in [CriticLaw(v) for v in (args.law or [c.value for c in CriticLaw])]:
        res = run(args.plant, law, args.legs, args.seed, ref, ActorLaw(args.actor))
        results.append(res)
        print(f"== {res['plant']} / critic {res['law']} / actor {res['actor']} (seed {res['seed']}): step median "
              f"{res['step_ms']['median']:.3f} ms, p99 {res['step_ms']['p99']:.3f} ms")
        if res['diverged']:
            print('   DIVERGED at', res['diverged'])
        for w in res['warnings']:
            print('   warning:', w)
        for i, leg in enumerate(res['legs']):
            print(f"  leg {i:2d}  D0 {leg['D0']:6.2f}  steps {leg['steps']:3d}  reached {leg['reached']!s:5}  "
                  f"gain error {leg['gain_error']:8.3f}  cost/optimum {leg['cost_ratio']:10.4f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
