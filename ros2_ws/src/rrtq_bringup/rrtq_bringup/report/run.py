"""`rrtq report RUN.mcap`: figures and a summary computed from the recording alone.

- ``map.png`` in the manner of RRT-QX Fig. 2: true obstacles (those that vanished
  hatched), the detected and the augmented obstacles, the RRT^X tree and the last path,
  the traversed path (the true one where recorded), the perception disc along it, the leg
  targets;
- ``timeseries.png``: forces, speed and distance to goal, disturbance, D_rob and its
  maximum, the learned weights (each panel only when its topics were recorded);
- ``margins.png`` (the margin against the legs' realised deviations) and, for
  ``learned_bound``, ``field.png`` (the learned field against the true one), the summary's
  ``margins`` entry (:mod:`rrtq_bringup.report.margins`);
- ``vf_lpc.png`` and the summary's ``vf_lpc`` entry for a vf_lpc run
  (:mod:`rrtq_bringup.report.vf_lpc`);
- with ``--video``, ``run.mp4`` or ``run.gif`` (:mod:`rrtq_bringup.report.video`);
- ``summary.json``: path length, control effort, clearance against the true obstacles,
  time to goal, legs — from the recorded messages and the scenario embedded in the file;
  the path, clearance and time to goal of the true state (/odom/truth) where recorded,
  not of the robot's noisy measurement (/odom).
"""

from __future__ import annotations

import json
import math
import pathlib

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle, Polygon as PolygonPatch  # noqa: E402

from rrtq_bringup.leg_table import LegTable, leg_table  # noqa: E402
from rrtq_bringup.leg_table import summary as leg_summary  # noqa: E402
from rrtq_bringup.run_data import RunData, embedded_scenario, read_run, recorded_scenario  # noqa: E402
from rrtq_bringup.mission import MissionConfig  # noqa: E402
from rrtq_bringup.report.margins import margins_summary  # noqa: E402
from rrtq_bringup.report.vf_lpc import is_vf_lpc, plot_vf_lpc, vf_lpc_summary  # noqa: E402
from rrtq_common.polygon_set import PolygonSet  # noqa: E402
from rrtq_common.yaml_reader import field_default  # noqa: E402



def _existence(data: RunData) -> dict[str, tuple[np.ndarray, float, float]]:
    """Every true obstacle ever published: polygon, first and last time it existed."""
    seen: dict[str, tuple[np.ndarray, float, float]] = {}
    true_t, _ = data.true_state()
    end = float(true_t[-1]) if true_t.size else 0.0
    sets = data.truth + [(math.inf, [])]
    for (t, obstacles), (t_next, _) in zip(sets, sets[1:]):
        for oid, poly in obstacles:
            first = seen[oid][1] if oid in seen else t
            seen[oid] = (poly, first, min(t_next, end))
    return seen


def true_clearance(data: RunData, robot_radius: float) -> np.ndarray:
    """Per true state sample: signed gap (m) from the robot's disc to the nearest true obstacle.

    Negative when they overlap, also inside an obstacle at robot radius 0. The samples are
    :meth:`RunData.true_state`'s.
    """
    true_t, true_x = data.true_state()
    out = np.full(true_t.size, math.inf)
    sets = data.truth + [(math.inf, [])]
    for (t, obstacles), (t_next, _) in zip(sets, sets[1:]):
        samples = np.flatnonzero((true_t >= t - 1e-9) & (true_t < t_next - 1e-9))
        if obstacles and samples.size:
            shapes = PolygonSet([poly for _, poly in obstacles])
            out[samples] = [shapes.nearest(p)[0] for p in true_x[samples, :2]]
    return out - robot_radius


def summarise(data: RunData, scenario: dict,
              goal_tolerance: float = field_default(MissionConfig, 'goal_tolerance')) -> dict:
    """The run's summary from its recording (the path, clearance and time to goal: the true state's)."""
    robot_radius = float(scenario.get('robot_radius', 0.0))
    true_t, true_x = data.true_state()
    positions = true_x[:, :2]
    clearance = true_clearance(data, robot_radius)
    goal = data.goal if data.goal is not None else np.asarray(scenario.get('goal', [np.nan] * 2))
    reached = np.flatnonzero(np.linalg.norm(positions - goal, axis=1) <= goal_tolerance)
    dt = float(np.median(np.diff(data.cmd_t))) if data.cmd_t.size > 1 else 0.0
    collided = bool(clearance.size and clearance.min() < 0.0)
    # Effort counts the commands the plant applied: those before the last step.
    applied = data.cmd_t < (data.odom_t[-1] - 1e-9 if data.odom_t.size else -np.inf)
    return {
        'sim_time_s': float(data.odom_t[-1]) if data.odom_t.size else 0.0,
        'steps': int(data.odom_t.size),
        'path_length_m': float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum()),
        'control_effort': float((data.cmd_u[applied] ** 2).sum() * dt),
        'min_clearance_m': float(clearance.min()) if np.isfinite(clearance).any() else None,
        'collided': collided,
        'time_to_goal_s': float(true_t[reached[0]]) if reached.size else None,
        'legs': int(data.leg_index.max()) + 1 if data.leg_index.size else 0,
        'max_d_rob_m': float(data.d_rob_max.max()) if data.d_rob_max.size else None,
        'max_abs_force_n': float(np.abs(data.cmd_u).max()) if data.cmd_u.size else 0.0,
        'force_limit_n': data.force_limit,
        'policy_events': {e: sum(1 for _, ev, _ in data.policy_events if ev == e)
                          for e in sorted({ev for _, ev, _ in data.policy_events})},
        'topics': data.topics,
    }


def plot_map(data: RunData, scenario: dict, path: pathlib.Path) -> None:
    fig, ax = plt.subplots(figsize=(8, 8))
    bounds = scenario.get('bounds')
    for poly, _first, last in _existence(data).values():
        vanished = data.odom_t.size and last < data.odom_t[-1] - 1e-9
        ax.add_patch(PolygonPatch(poly, closed=True, facecolor='none' if vanished else '0.35',
                                  edgecolor='0.2', hatch='//' if vanished else None, lw=1.0,
                                  zorder=2))
    believed = {oid: poly for _, obstacles in data.detected for oid, poly in obstacles}
    for oid, poly in believed.items():
        if oid not in _existence(data):      # mapped, but never there
            ax.add_patch(PolygonPatch(poly, closed=True, fill=False, ec='tab:red', ls=':',
                                      lw=1.0, zorder=2))
    if data.augmented:
        for _, poly in data.augmented[-1][1]:
            ax.add_patch(PolygonPatch(poly, closed=True, fill=False, ls='--', ec='tab:orange',
                                      lw=1.0, zorder=2))
    if data.detected:
        for _, poly in data.detected[-1][1]:
            ax.add_patch(PolygonPatch(poly, closed=True, fill=False, ec='tab:red', lw=1.2,
                                      zorder=3))
    if data.tree_segments is not None and len(data.tree_segments):
        from matplotlib.collections import LineCollection
        ax.add_collection(LineCollection(data.tree_segments, colors='0.8', lw=0.4, zorder=1))
    if data.plans:
        plan = data.plans[-1][1]
        ax.plot(plan[:, 0], plan[:, 1], '-', color='tab:green', lw=1.5, label='last RRT^X path')
    xy = data.true_state()[1][:, :2]
    if xy.size:
        ax.plot(xy[:, 0], xy[:, 1], '-', color='tab:blue', lw=1.8, label='traversed path',
                zorder=4)
        radius = float(scenario.get('perception_radius', 0.0))
        if radius > 0:
            for k in np.linspace(0, len(xy) - 1, 6).astype(int):
                ax.add_patch(Circle(xy[k], radius, fill=False, ec='tab:blue', alpha=0.25,
                                    ls=':'))
        ax.plot(*xy[0], 'o', color='tab:blue', ms=8, label='start')
    if data.leg_target.size and not is_vf_lpc(data):   # vf_lpc's 'leg' moves every step
        targets = np.unique(data.leg_target, axis=0)
        ax.plot(targets[:, 0], targets[:, 1], 'x', color='k', ms=6, label='leg targets')
    if data.goal is not None:
        ax.plot(*data.goal, '*', color='gold', mec='k', ms=16, label='goal', zorder=5)
    if bounds:
        ax.set_xlim(bounds['x'])
        ax.set_ylim(bounds['y'])
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(f"{scenario.get('name', '')}: grey true obstacles (hatched: vanished), red "
                 'detected (dotted: mapped but absent), orange augmented', fontsize=9)
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


_EVENT_STYLE = {'adopted': ('tab:green', '|'), 'rejected': ('tab:gray', 'x'),
                'reverted': ('tab:red', 'v'), 'hold': ('tab:purple', 'v'),
                'held_short': ('tab:orange', '^')}


def _mark_policy_events(ax: plt.Axes, data: RunData) -> None:
    """The guard's events (integral action armed: held_short) as marks along the bottom."""
    if not data.policy_events:
        return
    low = ax.get_ylim()[0]
    for event, (colour, marker) in _EVENT_STYLE.items():
        times = [t for t, e, _ in data.policy_events if e == event]
        if times:
            ax.plot(times, [low] * len(times), ls='', marker=marker, color=colour, ms=6,
                    clip_on=False, label=f'policy {event} ({len(times)})')
    for t, e, _ in data.policy_events:
        if e in ('reverted', 'hold'):
            ax.axvline(t, color=_EVENT_STYLE[e][0], lw=0.8, alpha=0.6)


def plot_timeseries(data: RunData, scenario: dict, path: pathlib.Path) -> None:
    panels = ['forces', 'motion']
    if data.dist_t.size and np.any(data.dist_d):
        panels.append('disturbance')
    if data.safety_t.size:
        panels.append('safety')
    if any(w.size for w in data.critic_w):
        panels.append('weights')
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 2.3 * len(panels)), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, panel in zip(axes, panels):
        if panel == 'forces':
            ax.plot(data.cmd_t, data.cmd_u[:, 0], label='$f_x$')
            ax.plot(data.cmd_t, data.cmd_u[:, 1], label='$f_y$')
            if np.isfinite(data.force_limit) and data.force_limit > 0:
                for sign in (1, -1):
                    ax.axhline(sign * data.force_limit, color='k', lw=0.6, ls=':')
            ax.set_ylabel('force [N]')
            _mark_policy_events(ax, data)
        elif panel == 'motion':
            ax.plot(data.odom_t, np.linalg.norm(data.odom_x[:, 2:], axis=1), label='speed [m/s]')
            if data.goal is not None:
                ax.plot(data.odom_t, np.linalg.norm(data.odom_x[:, :2] - data.goal, axis=1),
                        label='distance to goal [m]')
            if data.d.size:
                ax.plot(data.state_t, data.d, label='D (leg) ')
        elif panel == 'disturbance':
            for j in range(data.dist_d.shape[1]):
                ax.plot(data.dist_t, data.dist_d[:, j], label=f'$d_{j + 1}$')
            ax.set_ylabel('disturbance')
        elif panel == 'safety':
            ax.plot(data.safety_t, data.d_rob, label='$D_{rob}$')
            ax.plot(data.safety_t, data.d_rob_max, label='max $D_{rob}$')
            ax.set_ylabel('m')
        elif panel == 'weights':
            for name, ws in (('critic', data.critic_w), ('actor', data.actor_w),
                             ('disturbance actor', data.disturbance_w)):
                if any(w.size for w in ws):
                    ax.plot(data.state_t, [np.linalg.norm(w) for w in ws], label=f'|W| {name}')
            ax.set_ylabel('weight norm')
            _mark_policy_events(ax, data)
        ax.legend(loc='upper right', fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel('sim time [s]')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_legs(table: LegTable, path: pathlib.Path) -> None:
    """Per leg: cost against the Riccati optimum, and the learned gain's error."""
    index = table.column('index')
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    top.semilogy(index, table.column('ratio'), 'o-', ms=3)
    top.axhline(1.05, color='tab:red', ls=':', label='5 % above the optimum')
    top.set_ylabel('leg cost / optimum')
    top.legend(fontsize=8)
    bottom.plot(index, table.column('gain_error'), 'o-', ms=3, color='tab:orange')
    bottom.axhline(0.1, color='tab:red', ls=':', label='10 %')
    bottom.set_ylabel('|K̂ - K*| / |K*|')
    bottom.set_xlabel('leg')
    bottom.legend(fontsize=8)
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.suptitle('learned control against the finite-horizon Riccati optimum', fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(recording: str | pathlib.Path, out_dir: str | pathlib.Path | None = None,
           video_interval: float | None = None, video_fps: float = 10.0) -> dict:
    """Write the figures and summary for ``recording``; return the summary.

    ``video_interval`` (s of sim time per frame): also the animation of the run
    (:func:`rrtq_bringup.report.video.write_video`), named in the summary as ``video``.
    """
    recording = pathlib.Path(recording)
    out = pathlib.Path(out_dir) if out_dir else recording.parent / 'report'
    out.mkdir(parents=True, exist_ok=True)
    data = read_run(recording)
    scenario = embedded_scenario(recording)
    summary = summarise(data, scenario)
    plot_map(data, scenario, out / 'map.png')
    plot_timeseries(data, scenario, out / 'timeseries.png')
    if data.topics.get('/safety/status'):
        field = (recorded_scenario(recording)
                 if data.topics.get('/safety/disturbance_estimate') else None)
        margins = margins_summary(recording, field, float(scenario.get('robot_radius', 0.0)),
                                  out)
        if margins is not None:
            summary['margins'] = margins
    if data.critic_w and any(w.size for w in data.critic_w):
        table = leg_table(data, recorded_scenario(recording))
        if table.rows:
            legs = leg_summary(table)
            summary['legs_vs_optimum'] = {k: legs[k] for k in (
                'legs', 'median_ratio_last10', 'median_ratio_last10_complete',
                'median_gain_error_last10', 'ratios_last10')}
            plot_legs(table, out / 'legs.png')
    if is_vf_lpc(data):
        summary['vf_lpc'] = vf_lpc_summary(data, scenario)
        plot_vf_lpc(data, out / 'vf_lpc.png')
    if video_interval is not None:
        from rrtq_bringup.report.video import write_video
        summary['video'] = str(write_video(data, scenario, recording, out,
                                           interval=video_interval, fps=video_fps))
    (out / 'summary.json').write_text(json.dumps(summary, indent=2) + '\n')
    return summary
