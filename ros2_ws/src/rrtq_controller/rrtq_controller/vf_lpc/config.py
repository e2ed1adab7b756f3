"""Configuration of the VF-LPC controller: one frozen dataclass of settings."""

from __future__ import annotations

from dataclasses import dataclass

from rrtq_common.settings import check, setting

__all__ = ['LPCConfig']


@dataclass(frozen=True)
class LPCConfig:
    """Receding-horizon actor-critic (VF-LPC §IV-C, §IV-D) and its online compensation.

    Every field is a :func:`rrtq_common.settings.setting` (default, unit, range, doc);
    every number must also be finite.
    """

    horizon_steps: int = setting(20, low=1, doc='N, prediction steps of dt (the model\'s dt)')
    q_position: float = setting(100.0, unit='1/m^2', low=0.0, low_open=True,
                                doc='diagonal of Q in eq. (12): cost of position error, '
                                'each step')
    q_velocity: float = setting(20.0, unit='s^2/m^2', low=0.0,
                                doc='diagonal of Q in eq. (12): cost of velocity error, '
                                'each step')
    r_force: float = setting(1e-4, unit='1/N^2', low=0.0, low_open=True,
                             doc='R in eq. (12): cost of force, each step')
    barrier_weight: float = setting(50.0, low=0.0, doc='beta of eq. (23): cost of one '
                                    'obstacle at distance barrier_offset')
    barrier_rate: float = setting(8.0, unit='1/m', low=0.0, low_open=True,
                                  doc='eta of eq. (23)')
    barrier_offset: float = setting(0.15, unit='m', doc='d_0 of eq. (23), from the '
                                    'augmented obstacle')
    barrier_obstacles: int = setting(3, low=0, doc='K: the nearest K augmented obstacles '
                                     'carry a barrier')
    iterations: int = setting(2, low=1, doc='actor-critic iterations per control step (each '
                              'a critic sweep and an actor step)')
    force_limit: float = setting(1000.0, unit='N', low=0.0, low_open=True,
                                 doc='per axis: every command is in [-force_limit, force_limit]')
    compensate: bool = setting(True, doc='learn the residual online with the sparse GP '
                               '(eqs. 18-21); false: the nominal Koopman model alone')

    def __post_init__(self) -> None:
        check(self, finite=True)
