#!/usr/bin/env python3
"""How well the critic identifies the greedy gain of a fixed policy, plant by plant.

Why the heavy rovers' learning stalls (``docs/notes/2026-12-02-safe-learning-from-defaults.md``): on the
120 kg, 8 kg/s rover the gain error plateaus near 0.6 while the critic's fit residual is
about 1 %. This bench separates identification from the guard and the actor. The actor
holds one policy, the finite-horizon Riccati gain projected on the actor's time basis (the
best policy the actor can represent), and nothing is adopted; the robot is driven 12 legs
of 1.5-4.5 m with the default probing (Ornstein-Uhlenbeck, 1 s) held at a fixed
standard deviation; then the least-squares critic is fitted once to its window, exactly
as the controller does (the papers' critic, :mod:`rrtq_controller.bellman`).

Ground truth, not from the code under test: the value kernel P^π(τ) of the held policy,
from the Lyapunov differential equation dP/dτ = A_πᵀP + PA_π + M + KᵀRK, P(0) = P(T)
(``scipy.integrate.solve_ivp``, the true plant matrices), and its greedy gain R⁻¹BᵀP^π(τ),
which is what the critic's greedy gain R⁻¹Q̂_ux(τ) estimates. Per plant and probing level
(median over seeds): the relative error of the critic's greedy gain on τ in [2, 10] s,
and the critic's fit residual.

The probing levels are those of a mission: 20 N on the first leg decays by 0.85 per leg
to about 5 N by leg 9, 1 N by leg 19 and 0.2 N by leg 29.

Usage: ``.venv/bin/python benchmarks/critic_identification.py [--seeds 5]``; writes
``benchmarks/results/critic_identification.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from common import save
from rrtq_controller.config import ControllerConfig
from rrtq_controller.q_learning import QLearningController
from rrtq_testing import controller_reference as ref

T, DT, LEGS = 10.0, 0.05, 12
M, R, P_T = 10.0 * np.eye(4), 0.02 * np.eye(2), 0.5 * np.eye(4)
PLANTS = [  # (label, mass kg, stiffness N/m, damping kg/s, force limit N)
    ('no spring, 40 kg / 45 kg/s', 40.0, 0.0, 45.0, 1000.0),
    ('paper plant, 40 kg / 20 N/m / 45 kg/s', 40.0, 20.0, 45.0, 1000.0),
    ('no spring, 120 kg / 45 kg/s / 150 N', 120.0, 0.0, 45.0, 150.0),
    ('no spring, 110 kg / 15 kg/s / 200 N', 110.0, 0.0, 15.0, 200.0),
    ('no spring, 120 kg / 8 kg/s / 150 N', 120.0, 0.0, 8.0, 150.0),
]
PROBING = (5.0, 1.0, 0.2)
TAUS = np.linspace(2.0, T, 9)


def _held_riccati(ctrl: QLearningController, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Actor weights of the Riccati gain projected (least squares over τ) on the time basis."""
    Pf = ref.riccati(A, B, M, R, P_T, T)
    taus = np.linspace(0.0, T, 401)
    K = np.array([np.linalg.solve(R, B.T @ Pf(t)) for t in taus])          # (N, m, n)
    Phi = ctrl.time_basis.batch(taus)
    C = np.linalg.lstsq(Phi, K.reshape(len(taus), -1), rcond=None)[0]      # (L, m n)
    return -C.reshape(len(C), 2, 4).transpose(0, 2, 1).reshape(-1, 2)


def identify(mass: float, stiffness: float, damping: float, limit: float, probing: float,
             seed: int) -> dict:
    """Drive the held policy with fixed probing, fit the critic once, compare its greedy gain."""
    A, B = ref.rover(mass, stiffness, damping)
    cfg = ControllerConfig(M=10.0, R=0.02, P_T=0.5, force_limit=limit, probing_std=probing,
                           probing_decay=1.0, actor_warmup_legs=10 ** 6, widen_powers=())
    ctrl = QLearningController(cfg, 4, 2, 0, np.random.default_rng(seed))
    ctrl.set_weights(actor=_held_riccati(ctrl, A, B))
    ref.run_legs(ctrl, A, B, M, R, P_T, T, DT,
                 ref.random_legs(np.random.default_rng(seed + 5), LEGS, 1.5, 4.5), cfg.rho)
    ctrl.policy_evaluation()
    greedy = ref.improved_gain(A, B, M, R, P_T, T, ctrl.gain)
    errors = [np.linalg.norm(ctrl.critic_gain(tau) - greedy(tau)) / np.linalg.norm(greedy(tau))
              for tau in TAUS]
    # where the data are: the greedy force at the stored states (every 4th sample)
    tau0, x0 = (a[::4] for a in ctrl.critic.window.samples()[:2])
    true = np.array([greedy(t) @ x for t, x in zip(tau0, x0)])
    est = np.array([ctrl.critic_gain(t) @ x for t, x in zip(tau0, x0)])
    return {'greedy_error': float(np.mean(errors)), 'residual': float(ctrl.critic.residual),
            'force_error': float(np.linalg.norm(est - true) / np.linalg.norm(true))}


def render(rows: list[dict]) -> str:
    lines = ['Critic identification of a held policy (the projected Riccati gain), 12 legs with '
             'fixed probing, one least-squares fit; median over seeds of the relative error of '
             'the critic\'s greedy gain R⁻¹Q̂_ux(τ) against the true R⁻¹BᵀP^π(τ) on τ in [2, 10] s, '
             'of the greedy force at the stored states, ‖R⁻¹(Q̂_ux - BᵀP^π)x̄‖ over ‖R⁻¹BᵀP^πx̄‖ '
             '(root mean square over the samples: where the data are), and of the fit residual.', '',
             '| plant | ' + ' | '.join(f'probing {p:g} N: gain error / force error / residual'
                                       for p in PROBING) + ' |',
             '|---|' + '---|' * len(PROBING)]
    for label, *_ in PLANTS:
        cells = []
        for p in PROBING:
            r = next(r for r in rows if r['plant'] == label and r['probing'] == p)
            cells.append(f"{r['greedy_error']:.3f} / {r['force_error']:.3f} / {r['residual']:.4f}")
        lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, default=5)
    ap.add_argument('--no-save', action='store_true')
    args = ap.parse_args()
    rows = []
    for label, mass, k, c, limit in PLANTS:
        for p in PROBING:
            runs = [identify(mass, k, c, limit, p, s) for s in range(args.seeds)]
            rows.append({'plant': label, 'probing': p, 'seeds': args.seeds,
                         'greedy_error': float(np.median([r['greedy_error'] for r in runs])),
                         'residual': float(np.median([r['residual'] for r in runs])),
                         'force_error': float(np.median([r['force_error'] for r in runs])),
                         'per_seed': runs})
            print(f"{label:40s} probing {p:4g} N: greedy error {rows[-1]['greedy_error']:.3f}, "
                  f"force error {rows[-1]['force_error']:.3f}, "
                  f"residual {rows[-1]['residual']:.4f}", file=sys.stderr, flush=True)
    table = render(rows)
    print(table)
    if not args.no_save:
        save('critic_identification', {'legs': LEGS, 'taus': TAUS.tolist(), 'rows': rows}, table)
    return 0


if __name__ == '__main__':
    sys.exit(main())
