"""The ``safety:`` settings and one constructor for the three modes (what the safety node calls)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from rrtq_common.settings import check, setting

from .calibration import Calibration
from .conformal import CalibratedScale, ConformalConfig
from .learned import LearnedBoundPolicy
from .learned_data import Bounds, LearnedBoundConfig, ModelFrame
from .policy import ConformalPolicy, MarginMode, MarginPolicy, RunningMaxPolicy

__all__ = ['MarginConfig', 'make_policy', 'CALIBRATED_ADAPTATION']

CALIBRATED_ADAPTATION = 0.005
"""η of learned_bound's calibrated scale: Gibbs & Candès' γ. A miss lowers δ_t by η(1 − δ);
at η = 0.05 one gust's leg took δ_t from 0.05 to 0.0025, the quantile to the largest score
of the pool and the margin of narrow_gap's next legs to 10-17 m (docs/margins.md §10.1)."""


@dataclasses.dataclass(frozen=True)
class MarginConfig:
    """The scenario's ``safety:`` section (``docs/scenarios.md``; ``docs/margins.md``)."""

    margin: MarginMode = setting(MarginMode.RUNNING_MAX, doc='how the obstacles are grown: '
                                 'running_max (the paper), conformal, learned_bound')
    confidence: float = setting(0.95, low=0.0, high=1.0, low_open=True, high_open=True,
                                doc='1 - delta: conformal coverage of the next leg; '
                                'learned_bound: level of the simultaneous band')
    window: int = setting(50, low=1, doc='legs kept (conformal scores, learned_bound data)')
    initial_margin: float | None = setting(None, unit='m', low=0.0,
                                           doc='margin while the evidence certifies none; '
                                           'unset: the running max of D_rob')
    calibration: str | None = setting(None, doc='calibration file of earlier runs '
                                      '(absolute path; conformal: its scores fill the window; '
                                      'learned_bound: its normalized, refuted and prior scores '
                                      'calibrate the scale and the first legs)')
    conformal: bool = setting(True, doc='learned_bound: calibrate the scale of the tube '
                              'conformally (docs/margins.md section 10); false: the '
                              'uncalibrated bound')
    frame: ModelFrame = setting(ModelFrame.LEG_TARGET, doc='learned_bound: the one-step '
                                "model's frame (plant.spring_anchor)")
    prior_bound: float = setting(0.1, unit='m/s^2', low=0.0, low_open=True,
                                 doc='learned_bound: R, the field strength assumed possible '
                                 'where the data say nothing (Jha\'s assumption 3.1)')

    def __post_init__(self) -> None:
        check(self, finite=True)


def make_policy(mode: MarginMode | str, *, region: Bounds | None, dt: float,
                confidence: float = 0.95, window: int = 50,
                initial_margin: float | None = None,
                calibration: Calibration | Sequence[float] = (),
                frame: ModelFrame | str = ModelFrame.LEG_TARGET,
                n: int = 4, m: int = 2, prior_bound: float = 0.1,
                robot_radius: float = 0.5, conformal: bool = True) -> MarginPolicy:
    """The margin policy of ``mode``.

    Parameters
    ----------
    mode
        ``running_max`` | ``conformal`` | ``learned_bound``.
    region
        The scenario's bounds, m (learned_bound: where the field is learned; the other
        modes take None).
    dt
        The loop's step, s.
    confidence, window, initial_margin, calibration
        The ``safety:`` keys (1 − δ; legs kept; m, None: the running max; earlier runs'
        scores: a :class:`.calibration.Calibration`, or the raw scores alone).
    frame
        learned_bound: ``plant.spring_anchor``.
    prior_bound, robot_radius
        learned_bound: R (m/s²), the field assumed possible where the data say nothing; the
        robot's radius (m), for which obstacles the current leg's margin applies to.
    conformal
        learned_bound: calibrate the tube's scale (``safety.conformal``).
    """
    mode = MarginMode(mode)
    if not isinstance(calibration, Calibration):
        calibration = Calibration(tuple(calibration))
    if mode is MarginMode.RUNNING_MAX:
        return RunningMaxPolicy()
    if mode is MarginMode.CONFORMAL:
        return ConformalPolicy(ConformalConfig(confidence=confidence, window=window),
                               initial_margin, calibration.scores)
    if region is None:
        raise ValueError('learned_bound needs the region (the scenario\'s bounds)')
    return LearnedBoundPolicy(LearnedBoundConfig(region=region, dt=dt, frame=ModelFrame(frame),
                                                 confidence=confidence, window=window,
                                                 prior_bound=prior_bound,
                                                 robot_radius=robot_radius),
                              n, m, initial_margin,
                              CalibratedScale(ConformalConfig(
                                  confidence=confidence, window=window,
                                  adaptation=CALIBRATED_ADAPTATION),
                                              calibration.normalized, calibration.prior,
                                              calibration.refuted)
                              if conformal else None)
