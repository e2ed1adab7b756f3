"""One constructor for the three modes (what the safety node calls with the ``safety:`` keys)."""

from __future__ import annotations

from collections.abc import Sequence

from .conformal import ConformalConfig
from .learned import Bounds, LearnedBoundConfig, LearnedBoundPolicy, ModelFrame
from .policy import ConformalPolicy, MarginMode, MarginPolicy, RunningMaxPolicy

__all__ = ['make_policy']


def make_policy(mode: MarginMode | str, *, region: Bounds, dt: float,
                confidence: float = 0.95, window: int = 50,
                initial_margin: float | None = None, calibration: Sequence[float] = (),
                frame: ModelFrame | str = ModelFrame.LEG_TARGET,
                n: int = 4, m: int = 2) -> MarginPolicy:
    """The margin policy of ``mode``.

    Parameters
    ----------
    mode
        ``running_max`` | ``conformal`` | ``learned_bound``.
    region
        The scenario's bounds, m (learned_bound: where the field is learned).
    dt
        The loop's step, s.
    confidence, window, initial_margin, calibration
        The ``safety:`` keys (1 − δ; legs kept; m, None: the running max; earlier scores).
    frame
        learned_bound: ``plant.spring_anchor``.
    """
    mode = MarginMode(mode)
    if mode is MarginMode.RUNNING_MAX:
        return RunningMaxPolicy()
    if mode is MarginMode.CONFORMAL:
        return ConformalPolicy(ConformalConfig(confidence=confidence, window=window),
                               initial_margin, calibration)
    return LearnedBoundPolicy(LearnedBoundConfig(region=region, dt=dt, frame=ModelFrame(frame),
                                                 confidence=confidence, window=window),
                              n, m, initial_margin)
