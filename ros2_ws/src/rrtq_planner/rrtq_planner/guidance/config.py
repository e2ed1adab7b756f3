"""Configuration of the guiding level (VF-LPC §IV-A): one frozen dataclass, units in metadata."""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass, field

__all__ = ['GuidanceMode', 'GuidanceConfig', 'CurveStatus']


class GuidanceMode(enum.StrEnum):
    """What the planner hands the controller."""

    WAYPOINTS = 'waypoints'
    """The RRT^X path's vertices, one leg at a time (RRT-QX, today's default)."""
    GVF = 'gvf'
    """A reference trajectory rolled out on the kinodynamic composite vector field."""


class CurveStatus(enum.StrEnum):
    """How a rollout of the integral curve (eq. 17) ended."""

    REACHED = 'reached'
    """The curve reached the end of the desired path."""
    LENGTH = 'length'
    """The requested arclength was rolled out before the end of the path."""
    STALLED = 'stalled'
    """No progress along the desired path over ``stall_distance`` of curve (a deadlock)."""


def _f(default: float, unit: str, low: float, high: float, doc: str, *,
       low_open: bool = False) -> float:
    return field(default=default, metadata={'unit': unit, 'low': low, 'high': high,
                                            'low_open': low_open, 'doc': doc})


@dataclass(frozen=True)
class GuidanceConfig:
    """Parameters of the kinodynamic composite guiding vector field and its rollout.

    Every field's metadata carries ``unit``, ``low``, ``high`` (closed range, ``low_open``
    when the low end is excluded) and ``doc``; ``planner.guidance`` keys are these names.
    """

    mode: GuidanceMode = GuidanceMode.WAYPOINTS
    k_path: float = _f(1.0, '1/m', 0.0, 100.0, 'gain k_p of the path-following field '
                       'chi_P = -E grad(phi) - k_p phi grad(phi) (Yao et al. 2022)',
                       low_open=True)
    k_obstacle: float = _f(1.0, '1/m', 0.0, 100.0, 'gain k_r of each obstacle field chi_R',
                           low_open=True)
    reactive_width: float = _f(1.0, 'm', 0.0, 20.0, 'distance from an augmented obstacle '
                               'to its reactive boundary R (where the field starts to bend)',
                               low_open=True)
    repulsive_offset: float = _f(0.1, 'm', 0.0, 5.0, 'distance from an augmented obstacle '
                                 'to its repulsive boundary Q (never crossed); below '
                                 'reactive_width')
    bump_rate: float = _f(1.0, '1', 0.0, 100.0, 'rate l of the bump functions '
                          'exp(-l/s), exp(-l/(1-s)) across the sandwiched region',
                          low_open=True)
    a_max: float = _f(2.0, 'm/s^2', 0.0, 100.0, 'acceleration limit: v^2 kappa <= a_max '
                      'along the reference, and |dv/dt| <= a_max', low_open=True)
    v_max: float = _f(2.0, 'm/s', 0.0, 50.0, 'desired (and largest) speed v_d of the '
                      'reference', low_open=True)
    virtual_gain: float = _f(2.0, '1/m', 0.0, 100.0, 'k_v of eq. (16): how fast a virtual '
                             "obstacle's field fades towards the real reactive boundary",
                             low_open=True)
    step: float = _f(0.05, 'm', 0.0, 1.0, 'arclength step h of the discrete integral '
                     'curve (eq. 17)', low_open=True)
    deadlock_epsilon: float = _f(1e-3, '1', 0.0, 1.0, 'eps of eq. (17): a field vector '
                                 'shorter than this inherits the previous direction',
                                 low_open=True)
    stall_distance: float = _f(20.0, 'm', 0.0, 1e4, 'curve length without progress along '
                               'the desired path that counts as a deadlock', low_open=True)
    horizon: float = _f(5.0, 's', 0.0, 600.0, 'length of the published reference',
                        low_open=True)
    dt: float = _f(0.05, 's', 0.0, 1.0, 'sample period of the reference (the control '
                   'period)', low_open=True)

    def __post_init__(self) -> None:
        object.__setattr__(self, 'mode', GuidanceMode(self.mode))
        for f in dataclasses.fields(self):
            if 'unit' not in f.metadata:
                continue
            value = getattr(self, f.name)
            lo, hi = f.metadata['low'], f.metadata['high']
            bad_low = value <= lo if f.metadata['low_open'] else value < lo
            if not math.isfinite(value) or bad_low or value > hi:
                bracket = '(' if f.metadata['low_open'] else '['
                raise ValueError(f'{f.name} must be in {bracket}{lo:g}, {hi:g}] '
                                 f"{f.metadata['unit']}, got {value!r}")
        if self.repulsive_offset >= self.reactive_width:
            raise ValueError(f'repulsive_offset ({self.repulsive_offset:g} m) must be below '
                             f'reactive_width ({self.reactive_width:g} m)')

    @property
    def min_turn_radius(self) -> float:
        """r_min = v_d² / a_max, m: the tightest turn taken at the desired speed."""
        return self.v_max ** 2 / self.a_max
