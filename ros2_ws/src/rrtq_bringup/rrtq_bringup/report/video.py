"""`rrtq report --video`: an animation of a run, from the recording alone.

One frame per ``interval`` seconds of simulated time, from t = 0 to the last odometry:
the robot (its disc and the perception disc) where the last ``/odom`` at or before the
frame's time puts it, its trail, the RRT^X tree and the path in force then, the true
obstacles that exist then (appearing and vanishing), the detected ones and the augmented
ones (growing with the margin), and the current leg target. Written with matplotlib's
animation writers: ``run.mp4`` through ffmpeg when it is installed, ``run.gif`` through
Pillow otherwise. A line on stderr every tenth of the frames tells the progress.
"""

from __future__ import annotations

import bisect
import pathlib
import struct
import sys
from collections.abc import Callable
from typing import Any, TextIO

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import animation  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402

from rrtq_bringup.run_data import RunData, _tree_segments  # noqa: E402

Sets = list[tuple[float, list[tuple[str, np.ndarray]]]]
ROBOT_COLOR = '#0000ff'    # the robot's disc: a colour nothing else in the frame has


def frame_times(t_end: float, interval: float) -> np.ndarray:
    """0, interval, 2 interval, ... up to ``t_end`` (inclusive, to 1 ns)."""
    if not interval > 0.0:
        raise ValueError(f'frame interval must be > 0, got {interval}')
    return np.arange(int(np.floor(t_end / interval + 1e-9)) + 1) * interval


def index_at(times: np.ndarray, t: float) -> int:
    """Index of the last of the sorted ``times`` at or before ``t`` (-1: none)."""
    return int(np.searchsorted(times, t + 1e-9, side='right')) - 1


def _set_at(sets: Sets, t: float) -> list[tuple[str, np.ndarray]]:
    k = bisect.bisect_right([s for s, _ in sets], t + 1e-9) - 1
    return sets[k][1] if k >= 0 else []


def _cdr_first_stamp(data: bytes, offset: int) -> float:
    """A header stamp read straight from CDR bytes (little or big endian)."""
    order = '<' if data[1] == 1 else '>'
    sec, nanosec = struct.unpack_from(order + 'iI', data, offset)
    return sec + nanosec * 1e-9


class TreeTimeline:
    """The recorded /planner/tree messages by sim time; each decoded only when drawn.

    A tree message has thousands of points: its stamp is read from the CDR bytes (the first
    marker's header, after the encapsulation and the sequence length) and the message is
    decoded once, the first time a frame needs it.
    """

    def __init__(self, recording: str | pathlib.Path) -> None:
        self._stamps: list[float] = []
        self._raw: list[Any] = []
        with open(recording, 'rb') as f:
            for schema, channel, message in make_reader(f).iter_messages(
                    topics=['/planner/tree'], log_time_order=True):
                count = struct.unpack_from('<I' if message.data[1] == 1 else '>I',
                                           message.data, 4)[0]
                if count:
                    self._stamps.append(_cdr_first_stamp(message.data, 8))
                    self._raw.append((schema, channel, message.data))
        order = np.argsort(self._stamps, kind='stable')
        self._stamps = [self._stamps[i] for i in order]
        self._raw = [self._raw[i] for i in order]
        self._factory = DecoderFactory()
        self._cached: tuple[int, np.ndarray | None] = (-1, None)

    def at(self, t: float) -> np.ndarray | None:
        """(E, 2, 2) segments of the last tree stamped at or before ``t``."""
        k = bisect.bisect_right(self._stamps, t + 1e-9) - 1
        if k < 0:
            return None
        if self._cached[0] != k:
            schema, channel, data = self._raw[k]
            msg = self._factory.decoder_for(channel.message_encoding, schema)(data)
            self._cached = (k, _tree_segments(msg))
        return self._cached[1]


def _progress(total: int, stream: TextIO) -> Callable[[int, int], None]:
    step = max(1, total // 10)

    def show(done: int, _total: int) -> None:
        done += 1
        if done % step == 0 or done == total:
            stream.write(f'rrtq: video {done}/{total} frames ({100 * done // total} %)\n')
            stream.flush()
    return show


def _polys(obstacles: list[tuple[str, np.ndarray]]) -> list[np.ndarray]:
    return [poly for _, poly in obstacles if len(poly) >= 3]


def write_video(data: RunData, scenario: dict, recording: str | pathlib.Path,
                out_dir: pathlib.Path, interval: float = 0.5, fps: float = 10.0,
                use_ffmpeg: bool | None = None, stream: TextIO = sys.stderr) -> pathlib.Path:
    """Write ``run.mp4`` (ffmpeg) or ``run.gif`` (Pillow) of the run; return its path.

    ``use_ffmpeg`` None: ffmpeg when matplotlib finds it. Frames: :func:`frame_times`.
    """
    if not data.odom_t.size:
        raise ValueError('the recording has no /odom: nothing to animate')
    times = frame_times(float(data.odom_t[-1]), interval)
    trees = TreeTimeline(recording)
    robot_radius = float(scenario.get('robot_radius', 0.0))
    perception = float(scenario.get('perception_radius', 0.0))
    fig, ax = plt.subplots(figsize=(6.4, 6.4), dpi=100)
    bounds = scenario.get('bounds')
    if bounds:
        ax.set_xlim(bounds['x'])
        ax.set_ylim(bounds['y'])
    else:
        lo, hi = data.odom_x[:, :2].min(axis=0) - 5.0, data.odom_x[:, :2].max(axis=0) + 5.0
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    tree = ax.add_collection(LineCollection([], colors='0.8', lw=0.4, zorder=1))
    truth = ax.add_collection(PolyCollection([], facecolors='0.35', edgecolors='0.2', zorder=2))
    augmented = ax.add_collection(PolyCollection([], facecolors='none', edgecolors='tab:orange',
                                                 linestyles='--', zorder=3))
    detected = ax.add_collection(PolyCollection([], facecolors='none', edgecolors='tab:red',
                                                lw=1.2, zorder=3))
    plan, = ax.plot([], [], '-', color='tab:green', lw=1.5, zorder=4, label='RRT^X path')
    trail, = ax.plot([], [], '-', color='tab:blue', lw=1.5, zorder=5, label='trail')
    target, = ax.plot([], [], 'x', color='k', ms=7, zorder=6, label='leg target')
    disc = ax.add_patch(Circle((0, 0), perception, fill=False, ec='tab:blue', ls=':',
                               alpha=0.5, zorder=5))
    robot = ax.add_patch(Circle((0, 0), max(robot_radius, 0.2), color=ROBOT_COLOR, zorder=7))
    if data.goal is not None:
        ax.plot(*data.goal, '*', color='gold', mec='k', ms=14, zorder=6, label='goal')
    ax.legend(loc='upper left', fontsize=7)
    title = ax.set_title('', fontsize=9)
    plans_t = np.array([t for t, _ in data.plans])
    name = scenario.get('name', '')

    def draw(frame: int) -> None:
        t = float(times[frame])
        k = index_at(data.odom_t, t)
        xy = data.odom_x[: k + 1, :2]
        trail.set_data(xy[:, 0], xy[:, 1])
        position = xy[-1] if len(xy) else data.odom_x[0, :2]
        robot.set_center(position)
        disc.set_center(position)
        segments = trees.at(t)
        tree.set_segments([] if segments is None else list(segments))
        truth.set_verts(_polys(_set_at(data.truth, t)))
        detected.set_verts(_polys(_set_at(data.detected, t)))
        augmented.set_verts(_polys(_set_at(data.augmented, t)))
        p = index_at(plans_t, t)
        path = data.plans[p][1] if p >= 0 else np.zeros((0, 2))
        plan.set_data(path[:, 0], path[:, 1])
        s = index_at(data.state_t, t)
        if s >= 0 and data.leg_target.size:
            target.set_data([data.leg_target[s, 0]], [data.leg_target[s, 1]])
        title.set_text(f'{name}  t = {t:6.2f} s')

    movie = animation.FuncAnimation(fig, draw, frames=len(times), blit=False, repeat=False)
    if use_ffmpeg is None:
        use_ffmpeg = animation.writers.is_available('ffmpeg')
    if use_ffmpeg:
        path, writer = out_dir / 'run.mp4', animation.FFMpegWriter(fps=fps)
    else:
        path, writer = out_dir / 'run.gif', animation.PillowWriter(fps=fps)
    out_dir.mkdir(parents=True, exist_ok=True)
    movie.save(str(path), writer=writer, progress_callback=_progress(len(times), stream))
    plt.close(fig)
    return path
