#!/usr/bin/env python3
"""Q-learning controller core against the Riccati optimum: gain error, leg cost, step time.

On the rover without a spring (stiffness 0, M = 10 I, R = 0.02 I, P(T) = 0.5 I, T = 10 s,
Δt = 0.05 s, ρ = 0.15; initial PD gain 40 N/m, 30 N s/m), each configuration drives 20
consecutive legs of 3-8 m in random directions (velocity carried across waypoint
switches) for a few seeds, on a true plant it never sees (exact zero-order hold). Per
leg: the gain error mean_τ ‖K̂(τ) - R⁻¹BᵀP(τ)‖_F / ‖R⁻¹BᵀP(τ)‖_F over the leg's steps, and
the leg cost (exact running cost ½∫x̄ᵀMx̄ + uᵀRu plus the optimal cost-to-go
½x̄ᵀP(τ_end)x̄ from where the leg ended) over the optimum ½x̄0ᵀP(T)x̄0 — the definitions of
``rrtq_bringup.leg_costs``. Also the wall time of ``QLearningController.step`` (median,
p99). Configurations:

- ``paper``: the papers' laws, normalised-gradient critic RRT-QX (22) (α_c = 90) and
  gradient actor (23) (α_a = 1.2);
- ``gradient+whitened``: the papers' critic with the whitened actor;
- ``least_squares``: the recursive least-squares critic with the whitened actor (default).

Plus one run of the paper's laws over 150 legs: does the gradient critic get there later?

Usage: ``.venv/bin/python benchmarks/controller_bench.py [--seeds 0 1 2] [--legs 20]
[--long-legs 150]``; writes ``benchmarks/results/controller.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import save, time_steps  # noqa: E402
from rrtq_testing import controller_reference  # noqa: E402

from rrtq_controller.config import ActorLaw, ControllerConfig, CriticLaw  # noqa: E402
from rrtq_controller.q_learning import QLearningController  # noqa: E402

M, R, P_T, PD = 10.0, 0.02, 0.5, (40.0, 30.0)
CONFIGS = {
    'paper': (CriticLaw.GRADIENT, ActorLaw.GRADIENT),
    'gradient+whitened': (CriticLaw.GRADIENT, ActorLaw.WHITENED),
    'least_squares': (CriticLaw.LEAST_SQUARES, ActorLaw.WHITENED),
}


def run(name: str, seed: int, legs: int, ref) -> dict:
    """One configuration, one seed: per-leg records and step times."""
    critic, actor = CONFIGS[name]
    k0 = ((PD[0], 0.0, PD[1], 0.0), (0.0, PD[0], 0.0, PD[1]))
    cfg = ControllerConfig(M=M, R=R, P_T=P_T, critic_law=critic, actor_law=actor,
                           initial_gain=k0, probing_std=20.0)
    A, B = ref.rover(stiffness=0.0)
    ctrl = QLearningController(cfg, 4, 2, 0, np.random.default_rng(seed))
    times = time_steps(ctrl)
    # The critic's own greedy gain R⁻¹Q̂_ux(τ) (what the actor is drawn to, once the critic
    # is trusted) at the end of every leg, over τ in [T/2, T] where the legs run.
    Pf = ref.riccati(A, B, M * np.eye(4), R * np.eye(2), P_T * np.eye(4), cfg.horizon)
    taus = np.linspace(0.5 * cfg.horizon, cfg.horizon, 11)
    K = [np.linalg.solve(R * np.eye(2), B.T @ Pf(t)) for t in taus]
    critic_errors: list[float] = []
    trusted: list[bool] = []
    start_leg = ctrl.start_leg

    def start(x0, t):
        if ctrl.leg_index >= 0:
            critic_errors.append(float(np.mean([np.linalg.norm(ctrl.critic_gain(tt) - k)
                                                / np.linalg.norm(k) for tt, k in zip(taus, K)])))
        start_leg(x0, t)
        if ctrl.leg_index > 0:
            trusted.append(bool(ctrl.critic_trusted))

    ctrl.start_leg = start  # type: ignore[method-assign]
    diverged = None
    try:
        records = ref.run_legs(ctrl, A, B, M * np.eye(4), R * np.eye(2), P_T * np.eye(4),
                               cfg.horizon, cfg.dt,
                               ref.random_legs(np.random.default_rng(seed + 1000), legs), cfg.rho)
    except ref.Diverged as exc:
        records, diverged = exc.records, str(exc)
    start(np.zeros(4), 0.0)   # the critic after the last leg
    ms = 1e3 * np.asarray(times)
    return {
        'config': name, 'critic_law': critic.value, 'actor_law': actor.value, 'seed': seed,
        'warnings': ctrl.check_gains(), 'diverged': diverged,
        'legs': [{'D0': float(np.linalg.norm(r.x0)), 'steps': r.steps, 'reached': r.reached,
                  'gain_error': float(r.gain_error), 'cost_ratio': float(r.cost_ratio),
                  'critic_gain_error': critic_errors[i] if i < len(critic_errors) else None,
                  'critic_trusted_after': trusted[i] if i < len(trusted) else None}
                 for i, r in enumerate(records)],
        'step_ms': {'median': float(np.median(ms)), 'p99': float(np.percentile(ms, 99)),
                    'max': float(ms.max()), 'steps': int(ms.size)},
    }


def _per_leg(runs: list[dict], legs: int, key: str) -> np.ndarray:
    """(seeds, legs) array of one per-leg quantity (nan where a run stopped early)."""
    out = np.full((len(runs), legs), np.nan)
    for i, r in enumerate(runs):
        vals = [np.nan if leg[key] is None else float(leg[key]) for leg in r['legs']]
        out[i, :len(vals)] = vals
    return out


def tables(by_config: dict[str, list[dict]], legs: int) -> tuple[str, dict]:
    """The Markdown tables and the aggregate numbers."""
    agg: dict[str, dict] = {}
    lines = ['Rover without a spring, 20 legs of 3-8 m per seed; mean over seeds '
             f'({", ".join(str(r["seed"]) for r in next(iter(by_config.values())))}).',
             '',
             '| law | gain error leg 1 / 5 / 10 / 20 | cost/optimum leg 1 / 5 / 10 / 20 | '
             'median cost/optimum legs 11-20 | legs in window | step ms median / p99 |',
             '|---|---|---|---|---|---|']
    for name, runs in by_config.items():
        ge, cr = _per_leg(runs, legs, 'gain_error'), _per_leg(runs, legs, 'cost_ratio')
        ce = _per_leg(runs, legs, 'critic_gain_error')
        tr = _per_leg(runs, legs, 'critic_trusted_after')
        reached = sum(sum(leg['reached'] for leg in r['legs']) for r in runs)
        ms = [r['step_ms'] for r in runs]
        med = float(np.median([r['step_ms']['median'] for r in runs]))
        p99 = float(np.median([r['step_ms']['p99'] for r in runs]))
        last = cr[:, legs // 2:]
        agg[name] = {
            'gain_error_mean_per_leg': np.nanmean(ge, axis=0).tolist(),
            'critic_gain_error_mean_per_leg': np.nanmean(ce, axis=0).tolist(),
            'critic_trusted_fraction_per_leg': np.nanmean(tr, axis=0).tolist(),
            'cost_ratio_mean_per_leg': np.nanmean(cr, axis=0).tolist(),
            'median_cost_ratio_last10': float(np.nanmedian(last)),
            'gain_error_last_leg': float(np.nanmean(ge[:, -1])),
            'legs_reached': reached, 'legs_total': legs * len(runs),
            'step_ms_median': med, 'step_ms_p99': p99, 'step_ms_per_seed': ms,
            'diverged': [r['diverged'] for r in runs if r['diverged']],
        }
        pick = [min(j, legs - 1) for j in (0, 4, 9, legs - 1)]
        g = ' / '.join(f'{np.nanmean(ge[:, j]):.3f}' for j in pick)
        c = ' / '.join(f'{np.nanmean(cr[:, j]):.4f}' for j in pick)
        lines.append(f'| {name} | {g} | {c} | {agg[name]["median_cost_ratio_last10"]:.4f} | '
                     f'{reached}/{legs * len(runs)} | {med:.3f} / {p99:.2f} |')
    lines += ['', 'Per leg (mean over seeds): actor gain error · cost/optimum · critic greedy '
              'gain error at the leg end (τ in [T/2, T]) · fraction of seeds whose critic '
              'was trusted (actor following it) after the leg', '',
              '| leg | ' + ' | '.join(by_config) + ' |',
              '|---|' + '---|' * len(by_config)]
    for j in range(legs):
        cells = []
        for name in by_config:
            a = agg[name]
            cells.append(f"{a['gain_error_mean_per_leg'][j]:.3f} · "
                         f"{a['cost_ratio_mean_per_leg'][j]:.4f} · "
                         f"{a['critic_gain_error_mean_per_leg'][j]:.3f} · "
                         f"{a['critic_trusted_fraction_per_leg'][j]:.2f}")
        lines.append(f'| {j + 1} | ' + ' | '.join(cells) + ' |')
    warn = sorted({w for runs in by_config.values() for r in runs for w in r['warnings']})
    if warn:
        lines += [''] + [f'Warning from the core: {w}' for w in warn]
    return '\n'.join(lines), agg


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    ap.add_argument('--legs', type=int, default=20)
    ap.add_argument('--config', choices=sorted(CONFIGS), action='append')
    ap.add_argument('--long-legs', type=int, default=150,
                    help="one longer run of the paper's laws (first seed); 0: none")
    args = ap.parse_args()
    ref = controller_reference
    by_config: dict[str, list[dict]] = {}
    for name in args.config or list(CONFIGS):
        for seed in args.seeds:
            t0 = time.perf_counter()
            res = run(name, seed, args.legs, ref)
            print(f'{name} seed {seed}: {time.perf_counter() - t0:.1f} s wall, '
                  f"last leg gain error {res['legs'][-1]['gain_error']:.3f}, "
                  f"cost ratio {res['legs'][-1]['cost_ratio']:.4f}", flush=True)
            by_config.setdefault(name, []).append(res)
    table, agg = tables(by_config, args.legs)
    long_run = None
    if args.long_legs:
        res = run('paper', args.seeds[0], args.long_legs, ref)
        pick = sorted({j for j in (20, 50, 100, 150, args.long_legs) if j <= len(res['legs'])})
        long_run = {'config': 'paper', 'seed': args.seeds[0], 'legs': len(res['legs']),
                    'at_leg': pick,
                    'gain_error': [res['legs'][j - 1]['gain_error'] for j in pick],
                    'critic_gain_error': [res['legs'][j - 1]['critic_gain_error'] for j in pick],
                    'cost_ratio': [res['legs'][j - 1]['cost_ratio'] for j in pick],
                    'critic_trusted': [res['legs'][j - 1]['critic_trusted_after'] for j in pick]}
        table += (f"\n\nThe paper's laws over {len(res['legs'])} legs (seed {args.seeds[0]}): "
                  'leg · actor gain error · critic greedy gain error · cost/optimum · trusted\n\n'
                  '| leg | actor gain error | critic gain error | cost/optimum | trusted |\n'
                  '|---|---|---|---|---|\n' + '\n'.join(
                      f'| {j} | {g:.3f} | {c:.3f} | {r:.4f} | {t} |' for j, g, c, r, t in zip(
                          pick, long_run['gain_error'], long_run['critic_gain_error'],
                          long_run['cost_ratio'], long_run['critic_trusted'])))
    save('controller', {'plant': {'model': 'rover', 'mass': 40.0, 'stiffness': 0.0,
                                  'damping': 45.0},
                        'cost': {'M': M, 'R': R, 'P_T': P_T, 'horizon': 10.0, 'dt': 0.05,
                                 'rho': 0.15, 'initial_pd_gain': PD},
                        'legs': args.legs, 'seeds': args.seeds, 'summary': agg,
                        'paper_long_run': long_run,
                        'runs': [r for runs in by_config.values() for r in runs]}, table)
    return 0


if __name__ == '__main__':
    sys.exit(main())
