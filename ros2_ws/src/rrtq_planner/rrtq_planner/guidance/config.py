"""Configuration of the guiding level (VF-LPC §IV-A): one frozen dataclass of settings."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from rrtq_common.settings import check, setting

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


@dataclass(frozen=True)
class GuidanceConfig:
    """Parameters of the kinodynamic composite guiding vector field and its rollout.

    Every field is a :func:`rrtq_common.settings.setting` (default, unit, range, doc);
    ``planner.guidance`` keys are these names.
    """

    mode: GuidanceMode = setting(GuidanceMode.WAYPOINTS,
                                 doc='what the planner hands the controller')
    k_path: float = setting(
        1.0, unit='1/m', low=0.0, high=100.0, low_open=True,
        doc='gain k_p of the path-following field chi_P = -E grad(phi) - k_p phi grad(phi) '
        '(Yao et al. 2022)')
    k_obstacle: float = setting(1.0, unit='1/m', low=0.0, high=100.0, low_open=True,
                                doc='gain k_r of each obstacle field chi_R')
    reactive_width: float = setting(
        1.0, unit='m', low=0.0, high=20.0, low_open=True,
        doc='distance from an augmented obstacle to its reactive boundary R (where the field '
        'starts to bend)')
    repulsive_offset: float = setting(
        0.1, unit='m', low=0.0, high=5.0,
        doc='distance from an augmented obstacle to its repulsive boundary Q (never crossed); '
        'below reactive_width')
    bump_rate: float = setting(
        1.0, unit='1', low=0.0, high=100.0, low_open=True,
        doc='rate l of the bump functions exp(-l/s), exp(-l/(1-s)) across the sandwiched region')
    a_max: float = setting(
        2.0, unit='m/s^2', low=0.0, high=100.0, low_open=True,
        doc='acceleration limit: v^2 kappa <= a_max along the reference, and |dv/dt| <= a_max')
    v_max: float = setting(2.0, unit='m/s', low=0.0, high=50.0, low_open=True,
                           doc='desired (and largest) speed v_d of the reference')
    virtual_gain: float = setting(
        2.0, unit='1/m', low=0.0, high=100.0, low_open=True,
        doc="k_v of eq. (16): how fast a virtual obstacle's field fades towards the real "
        'reactive boundary')
    step: float = setting(0.05, unit='m', low=0.0, high=1.0, low_open=True,
                          doc='arclength step h of the discrete integral curve (eq. 17)')
    deadlock_epsilon: float = setting(
        1e-3, unit='1', low=0.0, high=1.0, low_open=True,
        doc='eps of eq. (17): a field vector shorter than this inherits the previous direction')
    stall_distance: float = setting(
        20.0, unit='m', low=0.0, high=1e4, low_open=True,
        doc='curve length without progress along the desired path that counts as a deadlock')
    horizon: float = setting(5.0, unit='s', low=0.0, high=600.0, low_open=True,
                             doc='length of the published reference')
    dt: float = setting(0.05, unit='s', low=0.0, high=1.0, low_open=True,
                        doc='sample period of the reference (the control period)')

    def __post_init__(self) -> None:
        object.__setattr__(self, 'mode', GuidanceMode(self.mode))
        check(self, finite=True)
        if self.repulsive_offset >= self.reactive_width:
            raise ValueError(f'repulsive_offset ({self.repulsive_offset:g} m) must be below '
                             f'reactive_width ({self.reactive_width:g} m)')

    @property
    def min_turn_radius(self) -> float:
        """r_min = v_d² / a_max, m: the tightest turn taken at the desired speed."""
        return self.v_max ** 2 / self.a_max
