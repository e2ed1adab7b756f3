"""Configuration of the VF-LPC controller (frozen, validated, units in the field docs)."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ['LPCConfig']


@dataclass(frozen=True)
class LPCConfig:
    """Receding-horizon actor-critic (VF-LPC §IV-C, §IV-D) and its online compensation.

    Attributes
    ----------
    horizon_steps : int
        N, prediction steps of dt (the model's dt); >= 1.
    q_position, q_velocity : float
        Diagonal of Q in eq. (12): cost per m² of position error, per (m/s)² of velocity
        error, each step.
    r_force : float
        R in eq. (12): cost per N² of force, each step.
    barrier_weight : float
        beta of eq. (23): cost of one obstacle at distance ``barrier_offset``.
    barrier_rate : float
        eta of eq. (23), 1/m.
    barrier_offset : float
        d_0 of eq. (23), m from the augmented obstacle.
    barrier_obstacles : int
        K: the nearest K augmented obstacles carry a barrier.
    iterations : int
        Actor-critic iterations per control step (each a critic sweep and an actor step).
    force_limit : float
        N per axis: every command is in [-force_limit, force_limit].
    compensate : bool
        Learn the residual online with the sparse GP (eqs. 18-21); False: the nominal
        Koopman model alone.
    """

    horizon_steps: int = 20
    q_position: float = 100.0
    q_velocity: float = 20.0
    r_force: float = 1e-4
    barrier_weight: float = 50.0
    barrier_rate: float = 8.0
    barrier_offset: float = 0.15
    barrier_obstacles: int = 3
    iterations: int = 2
    force_limit: float = 1000.0
    compensate: bool = True

    def __post_init__(self) -> None:
        checks = {
            'horizon_steps': self.horizon_steps >= 1,
            'q_position': self.q_position > 0.0, 'q_velocity': self.q_velocity >= 0.0,
            'r_force': self.r_force > 0.0, 'barrier_weight': self.barrier_weight >= 0.0,
            'barrier_rate': self.barrier_rate > 0.0,
            'barrier_offset': math.isfinite(self.barrier_offset),
            'barrier_obstacles': self.barrier_obstacles >= 0,
            'iterations': self.iterations >= 1, 'force_limit': self.force_limit > 0.0}
        for key, ok in checks.items():
            value = getattr(self, key)
            if not ok or (isinstance(value, float) and not math.isfinite(value)):
                raise ValueError(f'{key}: invalid value {value!r}')
