"""The scenario's ``perception:`` section and the geometry of a 360° laser scan (no rclpy).

Shared by the simulator's side (the spawner casts the rays, :mod:`rrtq_sim.scan`) and the
robot's side (the obstacle mapper, :mod:`rrtq_planner.obstacle_map`): both must agree on
the beams and on which steps carry a scan, and neither may depend on the other.

The scan follows sensor_msgs/LaserScan (REP-117 for what a range means): beam ``i`` points
at ``angle_min + i * angle_increment`` in ``base_link``, counter-clockwise from x, with
``angle_min = -π`` and ``angle_increment = 2π / beams``; a beam with no return within
``range_max`` reads ``+inf``. The robot of this planar point-mass model has no heading, so
``base_link`` is axis-aligned with ``map``: a return at range r along beam θ is the point
``position + r (cos θ, sin θ)`` of the map.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from rrtq_common.settings import setting

__all__ = ['PerceptionSource', 'PerceptionConfig', 'beam_angles', 'beam_directions',
           'period_steps', 'scan_due']


class PerceptionSource(enum.StrEnum):
    """Where the robot's obstacle map comes from."""

    POLYGONS = 'polygons'
    """The spawner hands over whole true polygons met by the perception disc."""
    SCAN = 'scan'
    """A simulated 360° laser scan; the robot's obstacle mapper builds the map."""


@dataclass(frozen=True)
class PerceptionConfig:
    """``perception: {source, beams, range, rate, noise}``.

    ``range_max`` is the file's ``range`` and ``noise_std`` its ``noise``.
    """

    source: PerceptionSource = setting(PerceptionSource.POLYGONS,
                                       doc='polygons (the perception disc) or scan')
    beams: int = setting(360, low=3, doc='beams of the scan over 360 degrees')
    range_max: float | None = setting(None, unit='m', low=0.0, low_open=True,
                                      doc="the scan's maximum range (None: the "
                                      "scenario's perception_radius)")
    rate: float = setting(10.0, unit='Hz', low=0.0, low_open=True,
                          doc='scans per second (the period is a whole number of steps)')
    noise_std: float = setting(0.0, unit='m', low=0.0,
                               doc='standard deviation of the Gaussian range noise (seeded)')

    @property
    def angle_increment(self) -> float:
        """Angle between adjacent beams, rad."""
        return 2.0 * math.pi / self.beams


def beam_angles(beams: int) -> np.ndarray:
    """Angles of the ``beams`` beams, rad: ``-π + i · 2π / beams``."""
    return -math.pi + np.arange(beams) * (2.0 * math.pi / beams)


def beam_directions(beams: int) -> np.ndarray:
    """Unit vectors of the beams in ``base_link`` (= ``map`` axes), shape (beams, 2)."""
    angles = beam_angles(beams)
    return np.column_stack([np.cos(angles), np.sin(angles)])


def period_steps(rate: float, dt: float) -> int:
    """Steps between two scans: ``1 / (rate · dt)``, which must be a whole number >= 1.

    Raises
    ------
    ValueError
        When the period ``1 / rate`` is not a multiple of ``dt``.
    """
    if not (rate > 0.0 and dt > 0.0):
        raise ValueError(f'rate and dt must be > 0, got {rate!r}, {dt!r}')
    steps = 1.0 / (rate * dt)
    whole = round(steps)
    if whole < 1 or abs(steps - whole) > 1e-6 * max(1.0, steps):
        raise ValueError(f'the period 1/rate = {1.0 / rate:g} s must be a whole number '
                         f'(>= 1) of steps of dt = {dt:g} s')
    return int(whole)


def scan_due(stamp_ns: int, dt_ns: int, period: int) -> bool:
    """Whether the step stamped ``stamp_ns`` carries a scan (steps 0, period, 2 period...)."""
    return (int(round(stamp_ns / dt_ns)) % period) == 0
