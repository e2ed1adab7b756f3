"""`rrtq report`'s margin figures (issue 11, ``docs/margins.md`` §8).

- ``margins.png`` (every mode): the margin the obstacles are grown by over time (robot
  radius excluded) and the margin in force at each leg's start, against each leg's realised
  largest deviation (its score), a leg above its margin marked as a violation;
- ``field.png`` (``learned_bound``, when ``/safety/disturbance_estimate`` was recorded): the
  last estimate of the field against the true one (the scenario's ``disturbance: {model:
  field}`` bumps, the ground truth): the true and the learned field strength on the map, and
  per supported cell the true value against mean ± band (per axis).

The true field's values are compared in the estimate's own units: the residual the field
leaves over one step of the recorded plant (its zero-order-hold input matrix) divided by dt,
which is what the observer estimates (:mod:`rrtq_planner.margins.learned`).
"""

from __future__ import annotations

import pathlib
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rrtq_bringup.run_data import messages, safety_legs  # noqa: E402
from rrtq_common import topics  # noqa: E402

__all__ = ['read_estimates', 'true_field', 'plot_margins', 'plot_field',
           'margins_summary']


def _stamp(header: Any) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def read_estimates(recording: pathlib.Path) -> list[Any]:
    """The recorded ``/safety/disturbance_estimate`` messages, in time."""
    return messages(recording, topics.DISTURBANCE_ESTIMATE)


def grid(est: Any) -> np.ndarray:
    """Cell positions (nx ny, 2) of an estimate, k = i ny + j."""
    gx, gy = np.meshgrid(est.x0 + est.spacing * np.arange(est.nx),
                         est.y0 + est.spacing * np.arange(est.ny), indexing='ij')
    return np.column_stack([gx.ravel(), gy.ravel()])


def true_field(scenario: Any, cells: np.ndarray) -> np.ndarray | None:
    """The scenario's field at ``cells`` in the estimate's units (m/s², per axis), or None.

    The acceleration a(p) leaves the residual Γ_a a(p) over one step of the plant (zero-order
    hold); its velocity rows over dt is what the estimate's mean approximates.
    """
    from rrtq_sim.disturbance import DisturbanceModel
    from rrtq_sim.field import compose_input_matrix
    from rrtq_sim.plant import Plant

    dist = scenario.disturbance
    if dist.model is not DisturbanceModel.FIELD:
        return None
    cfg = scenario.plant
    dt = scenario.controller.dt
    plant = Plant(cfg.A, cfg.B, compose_input_matrix(None, cfg.n), dt, 1e9)
    accel = dist.field().acceleration(cells)
    return np.asarray(accel @ plant.gamma_d.T, dtype=float)[:, 2:4] / dt


def plot_margins(statuses: list[Any], robot_radius: float, path: pathlib.Path) -> None:
    """``margins.png``: margin over time against the legs' realised deviations."""
    t = np.array([_stamp(s.header) for s in statuses])
    margin = np.array([s.margin for s in statuses]) - robot_radius
    legs = safety_legs(statuses)
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(t, margin, color='tab:blue', lw=1.2, label='margin (obstacles grown by, - radius)')
    if legs:
        starts = np.array([leg.start for leg in legs] + [t[-1]])
        in_force = np.array([leg.margin for leg in legs])
        dev = np.array([leg.deviation for leg in legs])
        ax.hlines(in_force, starts[:-1], starts[1:], color='tab:green', lw=2,
                  label='margin in force at the leg start'
                  + (' (calibrated)' if any(leg.scale != 1.0 for leg in legs) else ''))
        tube = np.array([leg.tube for leg in legs])
        if (tube > 0).any():
            # learned_bound: the uncalibrated tube each leg was predicted at its start; the
            # calibrated margin is it times the scale (docs/margins.md §10).
            has = tube > 0
            ax.hlines(tube[has], starts[:-1][has], starts[1:][has], color='tab:orange', lw=1,
                      linestyles='dashed', label='tube predicted (uncalibrated)')
        mid = 0.5 * (starts[:-1] + starts[1:])
        miss = dev > in_force
        ax.plot(mid[~miss], dev[~miss], 'o', color='k', ms=4, label="leg's largest deviation")
        ax.plot(mid[miss], dev[miss], 'x', color='tab:red', ms=7, mew=2,
                label=f'above its margin ({int(miss.sum())} of {len(dev)} legs)')
    mode = statuses[-1].margin_mode if statuses else ''
    scale = (f', last scale {legs[-1].scale:.2f}' if any(leg.tube > 0 for leg in legs)
             else '')
    ax.set_title(f'safety margin ({mode}{scale}) against the realised deviations', fontsize=10)
    ax.set_xlabel('t (s)')
    ax.set_ylabel('m')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc='upper right')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_field(est: Any, truth: np.ndarray, path: pathlib.Path) -> None:
    """``field.png``: the learned field (mean, band) against the true one."""
    cells = grid(est)
    mean = np.column_stack([est.mean_x, est.mean_y])
    band = np.column_stack([est.band_x, est.band_y])
    supported = np.asarray(est.supported, dtype=bool)
    extent = (est.x0 - 0.5 * est.spacing, est.x0 + (est.nx - 0.5) * est.spacing,
              est.y0 - 0.5 * est.spacing, est.y0 + (est.ny - 0.5) * est.spacing)
    true_norm = np.linalg.norm(truth, axis=1).reshape(est.nx, est.ny).T
    mean_norm = np.linalg.norm(mean, axis=1).reshape(est.nx, est.ny).T
    top = max(float(true_norm.max()), float(mean_norm.max()), 1e-9)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.4))
    for ax, image, title in ((axes[0], true_norm, 'true |a| (scenario)'),
                             (axes[1], mean_norm, 'learned |mean|')):
        shown = ax.imshow(image, origin='lower', extent=extent, vmin=0, vmax=top, cmap='viridis')
        ax.set_title(title + ' (m/s²)', fontsize=9)
        ax.set_aspect('equal')
        fig.colorbar(shown, ax=ax, fraction=0.046)
    axes[1].plot(cells[supported, 0], cells[supported, 1], ',', color='w')
    ax = axes[2]
    idx = np.flatnonzero(supported)
    inside = np.abs(mean[idx] - truth[idx]) <= band[idx]
    for axis, colour in ((0, 'tab:blue'), (1, 'tab:orange')):
        ax.errorbar(truth[idx, axis], mean[idx, axis], yerr=band[idx, axis], fmt='.',
                    ms=3, lw=0.5, color=colour, alpha=0.6,
                    label=f"{'xy'[axis]}: {int(inside[:, axis].sum())}/{len(idx)} covered")
    lim = [min(float(truth[idx].min(initial=0)), -0.1), max(float(truth[idx].max(initial=0)), 0.1)]
    ax.plot(lim, lim, 'k:', lw=1)
    ax.set_xlabel('true (m/s²)')
    ax.set_ylabel('learned mean ± band (m/s²)')
    ax.set_title(f'supported cells at t = {_stamp(est.header):.1f} s '
                 f'(1 - δ = {est.confidence:.2f})', fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def margins_summary(recording: pathlib.Path, scenario: Any, robot_radius: float,
                    out: pathlib.Path) -> dict[str, Any] | None:
    """Write ``margins.png`` (and ``field.png`` for learned_bound); the summary entry.

    ``scenario``: the recorded scenario, parsed (:func:`rrtq_bringup.run_data.recorded_scenario`),
    for the true field; None skips ``field.png``.
    """
    statuses = messages(recording, topics.SAFETY_STATUS)
    if not statuses:
        return None
    plot_margins(statuses, robot_radius, out / 'margins.png')
    legs = safety_legs(statuses)
    summary: dict[str, Any] = {
        'mode': statuses[-1].margin_mode, 'legs': len(legs),
        'violations': int(sum(leg.deviation > leg.margin for leg in legs)),
        'mean_margin_m': float(np.mean([s.margin for s in statuses]) - robot_radius)}
    estimates = read_estimates(recording) if scenario is not None else []
    if estimates:
        est = estimates[-1]
        truth = true_field(scenario, grid(est))
        summary['estimates'] = len(estimates)
        if truth is not None:
            plot_field(est, truth, out / 'field.png')
            sup = np.asarray(est.supported, dtype=bool)
            mean = np.column_stack([est.mean_x, est.mean_y])[sup]
            band = np.column_stack([est.band_x, est.band_y])[sup]
            summary['field_supported_cells'] = int(sup.sum())
            summary['field_covered'] = float(np.mean(np.all(np.abs(mean - truth[sup]) <= band,
                                                            axis=1))) if sup.any() else None
    return summary
