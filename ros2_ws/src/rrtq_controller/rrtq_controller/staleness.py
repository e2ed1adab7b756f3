"""Free-running control: the age of the newest odometry, and what to do when it is stale (no rclpy).

``rrtq robot`` runs the controller on its own Δt timer against whatever publishes /odom.
Each tick steps the controller with the newest odometry while it is fresh; odometry older
than ``stale_steps`` Δt makes it command zero (the state the command would be for is
unknown, as Nav2's collision monitor does on a timed-out source), once saying so, and
control resumes with the next odometry.

The age is measured in the run's time, also when the run's clock stops with the plant that
published it (a killed simulator takes /clock with it): it is the wall time since the
odometry arrived times the pace at which the odometry's stamps have been advancing against
wall time (about 1 on wall time, F for a plant at F × real time). So a plant at 5 × real
time that vanishes is noticed 3Δt/5 of wall time after its last message.
"""

from __future__ import annotations

import collections
import enum
import statistics
from dataclasses import dataclass

from rrtq_common.settings import check, setting

__all__ = ['FreeRunConfig', 'Freshness', 'OdometryWatch', 'STALE_EVENT', 'RESUMED_EVENT']

STALE_EVENT = 'stale_odometry'
"""The /controller/state ``policy_event`` of the tick that went to zero force."""
RESUMED_EVENT = 'odometry_resumed'
"""The /controller/state ``policy_event`` of the first tick with fresh odometry again."""


@dataclass(frozen=True)
class FreeRunConfig:
    """The free-running controller's settings (``rrtq robot``)."""

    stale_steps: float = setting(3.0, low=0.0, low_open=True, doc='odometry older than this '
                                 'many steps dt (run time) is stale: the controller commands '
                                 'zero until fresh odometry arrives')
    watch_period_s: float = setting(0.01, unit='s', low=0.0, low_open=True, doc='wall time '
                                    'between two looks at the odometry\'s age (also when the '
                                    'run\'s clock has stopped)')

    def __post_init__(self) -> None:
        check(self)


class Freshness(enum.Enum):
    """What a look at the newest odometry found."""

    NONE = 'none'
    """No odometry yet: nothing to command."""
    FRESH = 'fresh'
    """Fresh: control with it."""
    RESUMED = 'resumed'
    """Fresh again after a stale spell (once): control resumes."""
    WENT_STALE = 'went_stale'
    """Older than the limit, for the first time since it was fresh: command zero, say so."""
    STALE = 'stale'
    """Still stale: keep commanding zero."""


class OdometryWatch:
    """The run-time age of the newest odometry against ``stale_steps`` steps ``dt``.

    The pace (run seconds per wall second) is the median of Δstamp / Δwall over the last
    ``window`` spans between arrivals, a span closing at the first arrival at least
    ``min_gap_s`` after it opened (arrivals bunched together by a busy machine are merged
    into one span, not dropped). The median leaves out what says nothing about the pace: a
    late joiner's replay of the publisher's history, all at once, whose span would make
    the pace look huge and any pause stale. Until ``min_spans`` spans are in, the pace is 1.

    Parameters
    ----------
    dt : float
        The control step Δt, s (> 0).
    stale_steps : float
        Odometry older than ``stale_steps`` Δt is stale (> 0).
    window : int
        Spans over which the pace is measured (>= 1).
    min_gap_s : float
        Wall time (s) a span lasts at least (>= 0).
    min_spans : int
        Spans needed before the pace is measured rather than taken as 1 (1..window).
    """

    def __init__(self, dt: float, stale_steps: float = 3.0, window: int = 21,
                 min_gap_s: float = 0.002, min_spans: int = 3) -> None:
        if (not dt > 0.0 or not stale_steps > 0.0 or window < 1 or not min_gap_s >= 0.0
                or not 1 <= min_spans <= window):
            raise ValueError(f'need dt > 0, stale_steps > 0, window >= 1, min_gap_s >= 0, '
                             f'1 <= min_spans <= window; got {dt}, {stale_steps}, {window}, '
                             f'{min_gap_s}, {min_spans}')
        self.limit = dt * stale_steps
        """Run time (s) after which odometry is stale."""
        self.min_gap_s = min_gap_s
        self.min_spans = min_spans
        self._ratios: collections.deque[float] = collections.deque(maxlen=window)
        self._opened: tuple[float, float] | None = None
        self._last: tuple[float, float] | None = None
        self._stale = False
        self._resumed = False

    @property
    def pace(self) -> float:
        """Run seconds per wall second over the recent arrivals (1 until measured)."""
        if len(self._ratios) < self.min_spans:
            return 1.0
        return statistics.median(self._ratios)

    @property
    def last_stamp(self) -> float | None:
        """Stamp (s, run time) of the newest odometry, None before the first."""
        return None if self._last is None else self._last[0]

    def arrived(self, stamp: float, wall: float) -> bool:
        """Odometry stamped ``stamp`` (s, run time) arrived at wall time ``wall`` (s).

        False for an odometry no newer than the newest one (a repeat): it does not make
        the odometry fresh.
        """
        if self._last is not None and stamp <= self._last[0]:
            return False
        if self._opened is None:
            self._opened = (stamp, wall)
        elif wall - self._opened[1] >= max(self.min_gap_s, 1e-9):
            self._ratios.append((stamp - self._opened[0]) / (wall - self._opened[1]))
            self._opened = (stamp, wall)
        self._last = (stamp, wall)
        if self._stale:
            self._stale, self._resumed = False, True
        return True

    def age(self, wall: float) -> float:
        """Run time (s) since the newest odometry at wall time ``wall`` (inf before any)."""
        if self._last is None:
            return float('inf')
        return max(0.0, wall - self._last[1]) * self.pace

    def wall_since_last(self, wall: float) -> float:
        """Wall time (s) since the newest odometry arrived (inf before any)."""
        return float('inf') if self._last is None else max(0.0, wall - self._last[1])

    def check(self, wall: float) -> Freshness:
        """What to do at wall time ``wall``: control, or command zero (and when to say so)."""
        if self._last is None:
            return Freshness.NONE
        if self.age(wall) > self.limit:
            if self._stale:
                return Freshness.STALE
            self._stale, self._resumed = True, False
            return Freshness.WENT_STALE
        if self._resumed:
            self._resumed = False
            return Freshness.RESUMED
        return Freshness.FRESH
