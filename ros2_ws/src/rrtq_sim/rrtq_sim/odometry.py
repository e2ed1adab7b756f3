"""What the robot's odometry measures: the true state with Gaussian noise.

The simulator publishes the measurement on /odom (with its covariance) and the true
state on /odom/truth. The noise is white: independent per axis and per step, zero mean,
standard deviations σ_p on the position and σ_v on the velocity (``plant.odometry_noise``).
Its generator is the run's own stream (:data:`ODOMETRY_STREAM`), so a run with the same
seed measures the same noise, and no other generator of the run is disturbed by it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.settings import check, setting

__all__ = ['ODOMETRY_STREAM', 'OdometryNoiseConfig', 'OdometryNoise', 'odometry_rng']

ODOMETRY_STREAM = 1
"""The odometry noise draws from ``numpy.random.default_rng([seed, ODOMETRY_STREAM])``:
a stream of the run's seed apart from ``default_rng(seed)``, which the disturbance
injector and the controller use."""


@dataclass(frozen=True, kw_only=True)
class OdometryNoiseConfig:
    """``plant.odometry_noise``: the standard deviations of the measurement (0: exact)."""

    position_std: float = setting(0.0, unit='m', low=0.0, doc='odometry noise: standard '
                                  'deviation of the measured position, per axis')
    velocity_std: float = setting(0.0, unit='m/s', low=0.0, doc='odometry noise: standard '
                                  'deviation of the measured velocity, per axis')

    def __post_init__(self) -> None:
        check(self, finite=True)


def odometry_rng(seed: int) -> np.random.Generator:
    """The generator of the odometry noise of a run with ``seed``."""
    return np.random.default_rng([int(seed), ODOMETRY_STREAM])


class OdometryNoise:
    """One measurement per step of the planar state (p_x, p_y, v_x, v_y).

    Parameters
    ----------
    config : OdometryNoiseConfig
    rng : numpy.random.Generator
        The noise's generator (:func:`odometry_rng`); four standard normal draws per
        :meth:`measure` when any deviation is positive, none otherwise.
    """

    def __init__(self, config: OdometryNoiseConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._scale = np.array([config.position_std, config.position_std,
                                config.velocity_std, config.velocity_std])
        self._exact = not bool(np.any(self._scale > 0.0))

    @property
    def exact(self) -> bool:
        """No noise: the measurement is the state itself."""
        return self._exact

    @property
    def position_variance(self) -> float:
        """σ_p², m²: the diagonal of the measured pose's covariance for x and y."""
        return self.config.position_std ** 2

    @property
    def velocity_variance(self) -> float:
        """σ_v², m²/s²: the diagonal of the measured twist's covariance for x and y."""
        return self.config.velocity_std ** 2

    def measure(self, x: npt.ArrayLike) -> np.ndarray:
        """The measured (p_x, p_y, v_x, v_y) of the state ``x`` (its first four components).

        Exact (no noise configured), it is the state's own values, bit for bit.
        """
        state = np.array(np.asarray(x, dtype=float).reshape(-1)[:4])
        if state.shape != (4,):
            raise ValueError(f'x must have at least 4 components, got {np.shape(x)}')
        if self._exact:
            return state
        return state + self._scale * self._rng.standard_normal(4)
