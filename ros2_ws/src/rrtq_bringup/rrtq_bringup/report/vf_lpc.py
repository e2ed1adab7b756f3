"""`rrtq report` for a vf_lpc run: tracking, the GP's predictions, the path's acceleration.

From the recorded ``/controller/state`` (the vf_lpc fields, docs/design.md) and ``/odom``:

- ``vf_lpc.png``: the tracking error to the guidance reference; the one-step velocity
  prediction error of the identified model alone and of the learned model (nominal + GP
  mean) with the GP's 2σ band; the GP's dictionary size;
- the summary's ``vf_lpc`` entry: mean / p95 / max tracking error, one-step velocity
  prediction RMSE nominal against learned (and the reduction), the share of steps whose
  learned error is inside the 2σ band (per velocity component), the largest lateral
  acceleration v²κ of the driven path and the share of its samples at or below
  ``planner.guidance.a_max``, the largest jerk.
"""

from __future__ import annotations

import pathlib
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rrtq_bringup.run_data import RunData  # noqa: E402

__all__ = ['is_vf_lpc', 'vf_lpc_series', 'vf_lpc_summary', 'plot_vf_lpc']


def is_vf_lpc(data: RunData) -> bool:
    """The recording's controller is the vf_lpc variant."""
    return bool(data.states) and data.states[-1].variant == 'vf_lpc'


def _rows(states: list[Any], name: str) -> tuple[np.ndarray, np.ndarray]:
    """Times and (K, n) rows of an array field, steps where it is filled."""
    keep = [(s, np.asarray(getattr(s, name), dtype=float)) for s in states]
    keep = [(s, a) for s, a in keep if a.size]
    if not keep:
        return np.zeros(0), np.zeros((0, 4))
    t = np.array([s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s, _ in keep])
    return t, np.vstack([a for _, a in keep])


def vf_lpc_series(data: RunData) -> dict[str, np.ndarray]:
    """The vf_lpc fields as arrays (prediction rows only where a prediction was scored)."""
    states = data.states
    t_pred, err = _rows(states, 'prediction_error')
    _, nominal = _rows(states, 'nominal_error')
    _, std = _rows(states, 'prediction_std')
    return {'t': data.state_t, 'tracking': np.array([s.tracking_error for s in states]),
            'dictionary': np.array([s.gp_dictionary for s in states], dtype=float),
            't_pred': t_pred, 'learned_error': err, 'nominal_error': nominal, 'std': std}


def lateral_acceleration(odom_t: np.ndarray, odom_x: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """|v x a| / |v| (= v²κ) and the jerk's norm along the driven path, per odometry step.

    Acceleration and jerk by central differences of the recorded velocity; samples slower
    than 0.1 m/s are left out of v²κ (the curvature of a path at rest means nothing). A
    repeated stamp (the simulator republishes a step's odometry when an acknowledgement is
    late, docs/design.md) is one sample: only its first message is kept.
    """
    keep = np.r_[True, np.diff(odom_t) > 0.0] if len(odom_t) else np.zeros(0, bool)
    odom_t, odom_x = odom_t[keep], odom_x[keep]
    if len(odom_t) < 5:
        return np.zeros(0), np.zeros(0)
    v = odom_x[:, 2:4]
    acc = np.gradient(v, odom_t, axis=0)
    jerk = np.gradient(acc, odom_t, axis=0)
    speed = np.hypot(v[:, 0], v[:, 1])
    moving = speed > 0.1
    lateral = np.abs(v[:, 0] * acc[:, 1] - v[:, 1] * acc[:, 0])[moving] / speed[moving]
    return lateral, np.hypot(jerk[:, 0], jerk[:, 1])


def vf_lpc_summary(data: RunData, scenario: dict) -> dict[str, Any]:
    """The numbers of the module docstring (NaN where the run recorded nothing to judge)."""
    s = vf_lpc_series(data)
    out: dict[str, Any] = {}
    tracking = s['tracking']
    if tracking.size:
        out.update(tracking_mean_m=float(tracking.mean()),
                   tracking_p95_m=float(np.percentile(tracking, 95)),
                   tracking_max_m=float(tracking.max()))
    err, nominal, std = s['learned_error'], s['nominal_error'], s['std']
    if len(err):
        learned = float(np.sqrt(np.mean(err[:, 2:4] ** 2)))
        nom = float(np.sqrt(np.mean(nominal[:, 2:4] ** 2)))
        inside = np.abs(err[:, 2:4]) <= 2.0 * std[:, 2:4]
        out.update(velocity_rmse_nominal=nom, velocity_rmse_learned=learned,
                   prediction_error_reduction=(1.0 - learned / nom) if nom > 0 else float('nan'),
                   gp_2sigma_coverage=[float(c) for c in inside.mean(axis=0)],
                   gp_dictionary=int(s['dictionary'][-1]))
    lateral, jerk = lateral_acceleration(data.odom_t, data.odom_x)
    guidance = ((scenario.get('planner') or {}).get('guidance') or {})
    a_max = float(guidance.get('a_max', 2.0))
    if lateral.size:
        out.update(lateral_acceleration_max=float(lateral.max()), a_max=a_max,
                   lateral_within_a_max=float(np.mean(lateral <= a_max)),
                   jerk_max=float(jerk.max()))
    return out


def plot_prediction_error(ax: Any, s: dict[str, np.ndarray], j: int, name: str,
                          nominal: str) -> None:
    """One state's one-step prediction error: the nominal model's, with the GP, its 2σ band."""
    if len(s['t_pred']):
        t, err, band = s['t_pred'], s['learned_error'][:, j], 2.0 * s['std'][:, j]
        ax.fill_between(t, -band, band, color='tab:blue', alpha=0.2, label='GP 2σ')
        ax.plot(t, s['nominal_error'][:, j], lw=0.7, color='tab:red', label=nominal)
        ax.plot(t, err, lw=0.7, color='tab:blue', label='nominal + GP mean')
    ax.set_ylabel(f'{name} one-step\nerror [m/s]')
    ax.legend(loc='upper right', fontsize=8)


def plot_vf_lpc(data: RunData, path: pathlib.Path) -> None:
    """``vf_lpc.png``: tracking error, velocity prediction errors with the 2σ band, GP size."""
    s = vf_lpc_series(data)
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    axes[0].plot(s['t'], s['tracking'], lw=0.8)
    axes[0].set_ylabel('tracking error [m]')
    for ax, j, name in ((axes[1], 2, '$v_x$'), (axes[2], 3, '$v_y$')):
        plot_prediction_error(ax, s, j, name, 'nominal model')
    axes[3].plot(s['t'], s['dictionary'], lw=0.8)
    axes[3].set_ylabel('GP dictionary')
    axes[3].set_xlabel('sim time [s]')
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle('vf_lpc: tracking and the learned model', fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
