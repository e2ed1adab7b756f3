#!/usr/bin/env python3
"""Learned against the optimal feedback: robot-side rows flown twice, on the same layouts.

Each chosen row of ``benchmarks/robot_side.py`` runs twice, one ``rrtq bench`` each: from the
controller's defaults (learning, as in ``robot_side``), and with the actor held at the
infinite-horizon Riccati gain of the true plant (``controller.initial_gain`` from scipy's
``solve_continuous_are`` for the row's mass, damping and spring and the controller's default
M and R; ``controller.alpha_a`` 1e-9, so the actor does not move from it; no probing). The
safety shell (watch, brake, keep-off, margin) is the same in both. Where the Riccati gain
meets a row's targets and learning does not, the learner is what fails the row, not the
planner, the margin or the plant; the table says how far the margins grew in each.

Usage: ``.venv/bin/python benchmarks/riccati_gain.py [--seeds 20] [--rows NAME ...]
[--runs DIR]``; writes ``benchmarks/results/riccati_gain.{json,md}``.
"""

from __future__ import annotations

import dataclasses
import pathlib
import sys

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from scipy.linalg import solve_continuous_are

from common import failures_and_commands, rows_benchmark
from robot_side import BASE, DURATION
from robot_side import ROWS as ROBOT_SIDE
from robot_side import table as robot_side_table
from rrtq_controller.config import ControllerConfig
from rrtq_sim.plant import PlantConfig

PLANT = {f.name: float(f.default) for f in dataclasses.fields(PlantConfig)
         if f.name in ('mass', 'damping', 'stiffness')}   # the simulator's defaults
M_DEFAULT, R_DEFAULT = float(ControllerConfig().M), float(ControllerConfig().R)
CHOSEN = ('110 kg, sine 0.1 Hz', 'rover, field bump')


def riccati_gain(settings: list[str]) -> np.ndarray:
    """K (2 x 4) of the infinite-horizon LQ problem of the row's plant, state (p, v)."""
    plant = dict(PLANT)
    for s in settings:
        key, _, value = s.partition('=')
        if key.startswith('plant.') and key[6:] in plant:
            plant[key[6:]] = float(value)
    m, c, k = plant['mass'], plant['damping'], plant['stiffness']
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-k / m * np.eye(2), -c / m * np.eye(2)]])
    B = np.vstack([np.zeros((2, 2)), np.eye(2) / m])
    R = R_DEFAULT * np.eye(2)
    P = solve_continuous_are(A, B, M_DEFAULT * np.eye(4), R)
    return np.linalg.solve(R, B.T @ P)


def flown_by_riccati(settings: list[str]) -> list[str]:
    """The row's settings with the actor held at the Riccati gain."""
    K = riccati_gain(settings)
    rows = ', '.join('[' + ', '.join(f'{v:.4g}' for v in row) + ']' for row in K)
    return [*settings, f'controller.initial_gain=[{rows}]', 'controller.alpha_a=0.000000001',
            'controller.probing_std=0']


ROWS: dict[str, tuple[str, list[str]]] = {}
for _name in CHOSEN:
    _label, _settings = ROBOT_SIDE[_name]
    ROWS[_name] = (f'{_label}: learned from the defaults', _settings)
    ROWS[f'{_name}, Riccati gain'] = (f'{_label}: the Riccati gain of the true plant',
                                      flown_by_riccati(_settings))


def largest_margin(run_dir: str) -> float:
    """m: the largest margin the safety node published in a run (``/safety/status``)."""
    path = pathlib.Path(run_dir) / 'run.mcap'
    if not path.exists():
        return float('nan')
    with path.open('rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return max((m.margin for *_, m in reader.iter_decoded_messages(
            topics=['/safety/status'])), default=float('nan'))


def render(rows: list[dict]) -> str:
    """robot_side's table, the margins each row's runs grew to, the failures and commands."""
    lines = ['Each row twice on the same layouts (`rrtq bench scenarios/defaults_only.yaml`, 8 '
             'random obstacles, `--set duration=400`), blind to the disturbance: learned from '
             "the defaults, and with the actor held at the Riccati gain of the true plant "
             '(scipy, the default M and R; no probing); the safety shell (watch, brake, '
             'keep-off, running-max margin) is the same in both. Last ten: each run\'s median '
             'over its last ten legs of the leg cost over the true Riccati policy flown through '
             'the same recorded disturbance.', '', *robot_side_table(rows), '',
             '| row | largest margin m: median (max) over the runs | goals cut off |',
             '|---|---|---|']
    for r in rows:
        margins = [largest_margin(run['dir']) for run in r['runs']]
        cut = sum('goal cut off' in (f.get('reason') or '')
                  for f in r['stats']['mission_failures'])
        lines.append(f"| {r['label']} | {np.nanmedian(margins):.2f} ({np.nanmax(margins):.2f}) "
                     f"| {cut} |")
    return '\n'.join(lines + failures_and_commands(rows))


def main() -> int:
    return rows_benchmark('riccati_gain', __doc__, ROWS, render, BASE, engine='local',
                          settings=(DURATION,))


if __name__ == '__main__':
    sys.exit(main())
