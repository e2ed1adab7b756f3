#!/usr/bin/env python3
"""Model mismatch (the VF-LPC paper's §VI-C analogue): identify at 40 kg, run at 60-80 kg.

The nominal model is fitted by EDMD on 30 s of probing of the 40 kg rover; the closed loop
(RRT^X path, guidance, vf_lpc) then runs on rovers of 60, 70 and 80 kg with two
acceleration bumps where the robot passes, with the online GP and without it. Reported
per run: one-step prediction error of the next state (position and velocity parts) by the
nominal model and by the learned model, the reduction, the share of velocity components
inside the learned model's 2-sigma band, tracking error to the guidance reference, time
to goal, clearance. Usage::

    .venv/bin/python benchmarks/vf_lpc_mismatch.py
"""

from __future__ import annotations

import sys

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from common import RESULTS, save  # noqa: E402

from rrtq_bringup.vf_lpc_harness import (Bump, identify_by_probing, rover_plant,  # noqa: E402
                                         run_closed_loop)
from rrtq_controller.vf_lpc import LPCConfig  # noqa: E402
from rrtq_common.geometry import polygon_from_circle  # noqa: E402

OBSTACLES = [polygon_from_circle((8.0, 1.0), 1.5, 16),
             np.array([[12.0, -6.0], [14.0, -6.0], [14.0, 3.0], [12.0, 3.0]]),
             polygon_from_circle((18.0, 5.0), 1.0, 16),
             polygon_from_circle((26.0, -2.0), 1.2, 16)]
BUMPS = [Bump((5.0, -1.0), 3.0, (0.0, 2.0)), Bump((20.0, 3.0), 3.0, (-1.5, 1.5)),
         Bump((30.0, 2.0), 3.0, (1.0, -2.0))]
START, GOAL, BOUNDS = (0.0, 0.0), (34.0, 3.0), (-5.0, 40.0, -10.0, 15.0)


def metrics(r) -> dict:
    pos_n = np.linalg.norm(r.nominal_error[:, :2], axis=1)
    pos_l = np.linalg.norm(r.learned_error[:, :2], axis=1)
    vel_n = np.linalg.norm(r.nominal_error[:, 2:4], axis=1)
    vel_l = np.linalg.norm(r.learned_error[:, 2:4], axis=1)
    covered = np.abs(r.learned_error[:, 2:4]) <= 2.0 * r.learned_std[:, 2:4]
    return {'reached': bool(r.reached), 'collided': bool(r.collided),
            'time_s': round(float(r.time_s), 2), 'min_clearance_m': float(r.min_clearance),
            'max_force_N': float(np.abs(r.commands).max()),
            'one_step_pos_nominal_mm': 1e3 * float(pos_n.mean()),
            'one_step_pos_learned_mm': 1e3 * float(pos_l.mean()),
            'one_step_vel_nominal_mps': float(vel_n.mean()),
            'one_step_vel_learned_mps': float(vel_l.mean()),
            'reduction': float(1.0 - vel_l.mean() / vel_n.mean()),
            'coverage_2sigma': float(covered.mean()),
            'tracking_mean_m': float(r.tracking_error.mean()),
            'tracking_max_m': float(r.tracking_error.max())}


def main() -> int:
    model = identify_by_probing(rover_plant(40.0), np.random.default_rng(0))
    rows, runs = [], {}
    for mass in (60.0, 70.0, 80.0):
        for comp in (True, False):
            r = run_closed_loop(rover_plant(mass), model, OBSTACLES, START, GOAL, BOUNDS,
                                bumps=BUMPS, duration=60.0, lpc=LPCConfig(compensate=comp))
            runs[(mass, comp)] = r
            rows.append({'mass_kg': mass, 'gp': comp, **metrics(r)})
            print(rows[-1], flush=True)
    table = ['| plant | GP | goal | collided | time s '
             '| one-step vel. error nominal / learned (m/s) | reduction | 2σ coverage '
             '| one-step pos. error nominal / learned (mm) '
             '| tracking mean / max (m) | min clearance (m) | max |u| (N) |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for x in rows:
        learned = x['gp']
        table.append(
            f"| {x['mass_kg']:.0f} kg | {'yes' if learned else 'no'} | {x['reached']} | "
            f"{x['collided']} | {x['time_s']:.2f} | {x['one_step_vel_nominal_mps']:.4f} / "
            f"{x['one_step_vel_learned_mps']:.4f} | "
            f"{(100 * x['reduction']):.0f} % | "
            f"{(100 * x['coverage_2sigma']):.1f} % | "
            f"{x['one_step_pos_nominal_mm']:.2f} / {x['one_step_pos_learned_mm']:.2f} | "
            f"{x['tracking_mean_m']:.3f} / {x['tracking_max_m']:.3f} | "
            f"{x['min_clearance_m']:.2f} | {x['max_force_N']:.0f} |")
    table += ['', 'Model identified at 40 kg by EDMD (30 s of probing). Without the GP the '
              'learned model is the nominal one (reduction 0, no band). Bumps: '
              + ', '.join(f'{b.value} m/s² at {b.center} r {b.radius} m' for b in BUMPS) + '.',
              '', '![mismatch](vf_lpc_mismatch.png)']
    figure(runs)
    save('vf_lpc_mismatch', {'rows': rows}, '\n'.join(table))
    print('\n'.join(table))
    return 0


def figure(runs) -> None:
    fig, ax = plt.subplots(2, 2, figsize=(12, 8))
    gp, nogp = runs[(70.0, True)], runs[(70.0, False)]
    t = 0.05 * np.arange(len(gp.nominal_error))
    ax[0, 0].plot(t, np.linalg.norm(gp.nominal_error[:, 2:4], axis=1), lw=0.8,
                  label='nominal model (identified at 40 kg)')
    ax[0, 0].plot(t, np.linalg.norm(gp.learned_error[:, 2:4], axis=1), lw=0.8,
                  label='with the online GP')
    ax[0, 0].set(title='70 kg: one-step velocity prediction error', xlabel='t (s)',
                 ylabel='m/s')
    ax[0, 0].legend()
    truth = gp.nominal_error[:, 2]                     # what the GP must explain, v_x
    mean = gp.nominal_error[:, 2] - gp.learned_error[:, 2]
    band = 2.0 * gp.learned_std[:, 2]
    ax[0, 1].fill_between(t, mean - band, mean + band, alpha=0.3, label='GP mean ± 2σ')
    ax[0, 1].plot(t, mean, lw=0.8, label='GP mean')
    ax[0, 1].plot(t, truth, 'k', lw=0.6, label='true residual')
    ax[0, 1].set(title='70 kg: residual of v_x over one step', xlabel='t (s)', ylabel='m/s')
    ax[0, 1].legend()
    for r, name in ((gp, 'with GP'), (nogp, 'without GP')):
        ax[1, 0].plot(0.05 * np.arange(len(r.tracking_error)), r.tracking_error, lw=0.8,
                      label=name)
    ax[1, 0].set(title='70 kg: distance to the guidance reference', xlabel='t (s)',
                 ylabel='m')
    ax[1, 0].legend()
    for poly in OBSTACLES:
        p = np.vstack((poly, poly[:1]))
        ax[1, 1].fill(p[:, 0], p[:, 1], color='0.6')
    for b in BUMPS:
        ax[1, 1].add_patch(plt.Circle(b.center, b.radius, color='orange', alpha=0.2))
    ax[1, 1].plot(gp.path[:, 0], gp.path[:, 1], 'k--', lw=0.8, label='RRT^X path')
    for mass in (60.0, 70.0, 80.0):
        r = runs[(mass, True)]
        ax[1, 1].plot(r.positions[:, 0], r.positions[:, 1], lw=0.9, label=f'{mass:.0f} kg, GP')
    ax[1, 1].set(title='paths (bumps in orange)', aspect='equal')
    ax[1, 1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(RESULTS / 'vf_lpc_mismatch.png', dpi=110)


if __name__ == '__main__':
    sys.exit(main())
