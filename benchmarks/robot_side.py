#!/usr/bin/env python3
"""The robot side blind to its disturbance, from the controller's defaults: twelve rows.

Each row is one ``rrtq bench`` of ``scenarios/defaults_only.yaml`` (a random 8-obstacle
layout per seed, no controller key: the defaults, ``measured_disturbance: false``) with its
plant and disturbance set by ``--set``; the robot side reads no simulator truth. Per row:
goals with their 95 % interval (Wilson), collisions, runs out of bounds, the largest command
over the actuator's limit, and the last ten legs' cost against the true Riccati policy flown
through the same recorded disturbance, odometry noise and actuation delay
(``rrtq_bringup.bench.control``; the referee reads ``/odom/truth``). Targets (issue 31):
>= 19/20 goals per row, no collision, none out of bounds, no command beyond the limit, the
last-ten median <= 1.10 (<= 1.05 without a disturbance).

Usage: ``.venv/bin/python benchmarks/robot_side.py [--seeds 20] [--engine ray|local]
[--rows NAME ...] [--runs DIR]``; writes ``benchmarks/results/robot_side.{json,md}``.
"""

from __future__ import annotations

import sys

from common import ROOT, failures_and_commands, rows_benchmark

BASE = ROOT / 'scenarios' / 'defaults_only.yaml'
NOSPRING = ['plant.stiffness=0']
PAPER = ['plant.stiffness=20']                   # the paper's rover (40 kg, 45 kg/s, 20 N/m)
HEAVY = ['plant.stiffness=0', 'plant.mass=110', 'plant.damping=15', 'plant.force_limit=200']
NOISY = ['plant.stiffness=0', 'plant.odometry_noise={position: 0.02, velocity: 0.05}',
         'plant.actuation_delay=0.1']
WHITE_05 = ['disturbance.model=gaussian', 'disturbance.amplitude=0.5']
SINE_01 = ['disturbance.model=sinusoid', 'disturbance.amplitude=0.5', 'disturbance.frequency=0.1']
ROWS: dict[str, tuple[str, list[str]]] = {
    'rover, white 0.5': ('rover without a spring, white Gaussian 0.5 m/s²', NOSPRING + WHITE_05),
    'rover, white 1.0': ('rover without a spring, white Gaussian 1.0 m/s²',
                         NOSPRING + ['disturbance.model=gaussian', 'disturbance.amplitude=1.0']),
    'rover, sine 0.1 Hz': ('rover without a spring, sinusoid 0.5 m/s² at 0.1 Hz',
                           NOSPRING + SINE_01),
    'rover, sine 0.2 Hz': ('rover without a spring, sinusoid 0.5 m/s² at 0.2 Hz',
                           NOSPRING + ['disturbance.model=sinusoid', 'disturbance.amplitude=0.5',
                                       'disturbance.frequency=0.2']),
    'rover, field bump': ('rover without a spring, a field bump of 1 m/s² across the route '
                          '(centre (0, 0), radius 6 m)',
                          NOSPRING + ['disturbance.model=field', 'disturbance.bumps=[{center: '
                                      '[0, 0], radius: 6.0, value: [0.7, -0.7]}]']),
    'paper plant, white 0.5': ("the paper's rover (20 N/m spring) at R = 0.02, white 0.5 m/s²",
                               PAPER + WHITE_05),
    'paper plant, sine 0.1 Hz': ("the paper's rover at R = 0.02, sinusoid 0.5 m/s² at 0.1 Hz",
                                 PAPER + SINE_01),
    '110 kg, white 0.5': ('110 kg / 15 kg/s / 200 N rover, white 0.5 m/s²', HEAVY + WHITE_05),
    '110 kg, sine 0.1 Hz': ('110 kg / 15 kg/s / 200 N rover, sinusoid 0.5 m/s² at 0.1 Hz',
                            HEAVY + SINE_01),
    'noisy + delay': ('rover without a spring, odometry noise 0.02 m / 0.05 m/s, a 2-step '
                      '(0.1 s) actuation delay, no disturbance', NOISY),
    'noisy + delay, white 0.5': ('the same, white Gaussian 0.5 m/s²', NOISY + WHITE_05),
    'noisy + delay, sine 0.1 Hz': ('the same, sinusoid 0.5 m/s² at 0.1 Hz', NOISY + SINE_01),
}
DURATION = 'duration=400'


def table(rows: list[dict]) -> list[str]:
    """The markdown table of the rows: goals, collisions, exits, commands, last ten, time."""
    lines = ['| row | goals (95 % CI) | collisions | out of bounds | largest command / limit '
             '| last ten / Riccati policy: median (p90) | within 5 % / 10 % | time to goal s '
             '(median) |', '|---|---|---|---|---|---|---|---|']
    for r in rows:
        s, c = r['stats'], r['stats'].get('control') or {}
        ci = s['success_rate_ci95']
        ci_text = f" ({100 * ci[0]:.0f}–{100 * ci[1]:.0f} %)" if ci else ''
        ttg = s['time_to_goal_s']['median']
        lines.append(
            f"| {r['label']} | {s['successes']}/{s['completed']}{ci_text} | {s['collisions']} | "
            f"{s.get('out_of_bounds', 0)} | {c.get('max_force_over_limit', float('nan')):.3f} | "
            f"{c.get('ratio_riccati_policy_median', float('nan')):.3f} "
            f"({c.get('ratio_riccati_policy_p90', float('nan')):.3f}) | "
            f"{c.get('within_5pct', 0)} / {c.get('within_10pct', 0)} of {c.get('runs', 0)} | "
            f"{'—' if ttg is None else f'{ttg:.1f}'} |")
    return lines


def render(rows: list[dict]) -> str:
    """The table of the rows, and the missions that failed."""
    lines = ['Every row from the controller\'s defaults, blind to the disturbance '
             '(`measured_disturbance: false`), on the random layouts of `rrtq bench '
             'scenarios/defaults_only.yaml` (8 obstacles, seeds as stated), `--set duration=400`. '
             'Last ten: each run\'s median over its last ten legs of the leg cost over the true '
             'Riccati policy flown through the same recorded disturbance, odometry noise and '
             'delay; the table gives the median over the runs and the runs within 5 % / 10 %.', '']
    return '\n'.join(lines + table(rows) + failures_and_commands(rows))


def main() -> int:
    return rows_benchmark('robot_side', __doc__, ROWS, render, BASE, engine='ray',
                          settings=(DURATION,))


if __name__ == '__main__':
    sys.exit(main())
