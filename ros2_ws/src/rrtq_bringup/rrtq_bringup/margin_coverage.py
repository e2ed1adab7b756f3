"""Coverage of the published safety margin, from a recording alone (issue 11).

``python -m rrtq_bringup.margin_coverage RUN.mcap [RUN.mcap ...]`` (or
:func:`coverage`) answers: on how many legs did the margin the safety node *published*
cover the deviation the robot *realised*, and is the miss rate compatible with δ?

Nothing is taken from the margin policy's own accounting (``leg_deviation``,
``leg_margin``, ``violations``):

* the **realised deviation** of a leg is recomputed from ``/odom`` and
  ``/controller/state``: at each odometry stamp t_k, D_rob (RRT-QX eq. 6) of the position
  from the straight line (start, target) of the controller's state of the step before
  (the leg that issued the command acting over [t_{k−1}, t_k), as the safety node reads
  it); a leg's deviation is the largest over its steps; legs with D0 <= 0 are not
  measured;
* the **margin in force** for a leg is the *least* margin published on ``/safety/status``
  while the leg ran (``margin`` minus the robot radius): a margin raised during the leg
  after a deviation exceeded it does not count as covering that deviation; for the
  conformal mode this is the margin at the leg's start (its ``leg_margin``).

A leg is covered when its realised deviation is at most its margin in force (1 mm of
tolerance for the float round trip through the messages). The verdict: the miss rate is
compatible with δ = 1 − confidence when the lower end of its two-sided 95 %
Clopper-Pearson interval is at most δ ("binomial slack"); δ is the scenario's
``safety.confidence`` (default 0.95) unless given.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import sys
from typing import Any

import numpy as np

from rrtq_planner.margins.coverage import binomial_interval
from rrtq_common.geometry import kinodynamic_distance

__all__ = ['LegCoverage', 'Coverage', 'leg_coverage', 'coverage', 'main']

TOLERANCE = 1e-3
"""m: a deviation this far above its margin still counts as covered (message round trip)."""


@dataclasses.dataclass(frozen=True)
class LegCoverage:
    """One leg: when it ran, what it realised, what was published for it."""

    index: int
    """The controller's leg index."""
    t_start: float
    t_end: float
    deviation: float
    """m, the largest D_rob over the leg, recomputed from /odom and /controller/state."""
    margin: float
    """m, the least margin published (robot radius excluded) while the leg ran."""

    @property
    def covered(self) -> bool:
        return bool(self.deviation <= self.margin + TOLERANCE)


@dataclasses.dataclass(frozen=True)
class Coverage:
    """The verdict of one or more recordings."""

    mode: str
    delta: float
    legs: list[LegCoverage]

    @property
    def misses(self) -> int:
        return sum(not leg.covered for leg in self.legs)

    @property
    def interval(self) -> tuple[float, float]:
        """95 % Clopper-Pearson interval of the miss rate (nan, nan without legs)."""
        if not self.legs:
            return (float('nan'), float('nan'))
        return binomial_interval(self.misses, len(self.legs))

    @property
    def passed(self) -> bool:
        """The miss rate is compatible with δ (lower end of its interval <= δ)."""
        return bool(self.legs) and self.interval[0] <= self.delta

    def as_dict(self) -> dict[str, Any]:
        lo, hi = self.interval
        return {'mode': self.mode, 'delta': self.delta, 'legs': len(self.legs),
                'misses': self.misses, 'miss_rate': self.misses / max(len(self.legs), 1),
                'interval': [lo, hi], 'passed': self.passed,
                'per_leg': [dataclasses.asdict(leg) | {'covered': leg.covered}
                            for leg in self.legs]}


def _t(header: Any) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def leg_coverage(odom: list[tuple[float, np.ndarray]], states: list[Any],
                 statuses: list[tuple[float, float]], robot_radius: float) -> list[LegCoverage]:
    """Per leg, the realised deviation and the least margin published while it ran.

    Parameters
    ----------
    odom
        (t s, position (2,) m) of every odometry message, in time.
    states
        /controller/state messages in time (``leg_index``, ``leg_start``, ``leg_target``,
        ``d0``, ``header``).
    statuses
        (t s, published margin m, robot radius included) of every /safety/status, in time.
    robot_radius
        m, subtracted from the published margins.
    """
    state_t = np.array([_t(s.header) for s in states])
    margin_at = {round(t, 6): m - robot_radius for t, m in statuses}
    legs: dict[int, list[float]] = {}
    order: list[int] = []
    for t, p in odom:
        # The controller's state of the step before: the last one stamped before t.
        i = int(np.searchsorted(state_t, t - 1e-6, side='right')) - 1
        if i < 0:
            continue
        s = states[i]
        if s.d0 <= 0.0:
            continue
        m = margin_at.get(round(t, 6))
        if m is None:
            continue
        d = kinodynamic_distance((s.leg_start.x, s.leg_start.y),
                                 (s.leg_target.x, s.leg_target.y), p)
        row = legs.get(s.leg_index)
        if row is None:
            legs[s.leg_index] = [t, t, d, m]
            order.append(s.leg_index)
        else:
            row[1], row[2], row[3] = t, max(row[2], d), min(row[3], m)
    return [LegCoverage(k, *legs[k]) for k in order]


def _read(recording: pathlib.Path) -> tuple[list, list, list, dict]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from rrtq_bringup.run_data import embedded_scenario

    factory = DecoderFactory()
    odom, states, statuses, last = [], [], [], None
    with open(recording, 'rb') as f:
        for schema, channel, message in make_reader(f).iter_messages(
                topics=['/odom', '/controller/state', '/safety/status'], log_time_order=True):
            msg = factory.decoder_for(channel.message_encoding, schema)(message.data)
            if channel.topic == '/odom':
                p = msg.pose.pose.position
                odom.append((_t(msg.header), np.array([p.x, p.y])))
            elif channel.topic == '/controller/state':
                states.append(msg)
            else:
                statuses.append((_t(msg.header), float(msg.margin)))
                last = msg
    scenario = embedded_scenario(recording) or {}
    return odom, sorted(states, key=lambda s: _t(s.header)), statuses, \
        {'scenario': scenario, 'mode': last.margin_mode if last is not None else ''}


def coverage(recordings: list[pathlib.Path], delta: float | None = None) -> Coverage:
    """The legs of every recording, and the verdict against δ.

    δ: given, or 1 − the first recording's ``safety.confidence`` (default 0.95).
    """
    legs: list[LegCoverage] = []
    mode = ''
    for rec in recordings:
        odom, states, statuses, meta = _read(pathlib.Path(rec))
        scenario = meta['scenario']
        if delta is None:
            delta = 1.0 - float((scenario.get('safety') or {}).get('confidence', 0.95))
        mode = mode or meta['mode']
        legs += leg_coverage(odom, states, statuses, float(scenario.get('robot_radius', 0.0)))
    return Coverage(mode, 0.05 if delta is None else delta, legs)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m rrtq_bringup.margin_coverage',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('recordings', nargs='+', type=pathlib.Path)
    parser.add_argument('--delta', type=float, default=None,
                        help='1 - confidence (default: the scenario\'s safety.confidence)')
    parser.add_argument('--json', action='store_true', help='print the per-leg table as JSON')
    args = parser.parse_args(argv)
    cov = coverage(args.recordings, args.delta)
    if args.json:
        print(json.dumps(cov.as_dict(), indent=1))
    else:
        for leg in cov.legs:
            print(f'leg {leg.index:3d}  t {leg.t_start:7.2f}-{leg.t_end:7.2f} s  deviation '
                  f'{leg.deviation:6.3f} m  margin {leg.margin:6.3f} m  '
                  f'{"covered" if leg.covered else "MISSED"}')
        lo, hi = cov.interval
        print(f'{cov.mode}: {cov.misses}/{len(cov.legs)} legs above their margin, rate '
              f'{cov.misses / max(len(cov.legs), 1):.3f} [{lo:.3f}, {hi:.3f}] vs delta '
              f'{cov.delta:.3f}: {"compatible" if cov.passed else "NOT compatible"}')
    return 0 if cov.passed else 1


if __name__ == '__main__':
    sys.exit(main())
