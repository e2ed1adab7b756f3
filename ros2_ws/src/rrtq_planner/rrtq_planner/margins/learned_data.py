"""``learned_bound``'s data: its settings, one leg's statistics, the estimate it publishes.

:class:`LearnedBoundConfig` (the scenario's ``safety.learned_bound``), :class:`ModelFrame`
(where the one-step model is time-invariant), :class:`LegData` (what
:class:`.learned.LearnedBoundPolicy` keeps of each leg of its window) and
:class:`FieldEstimate` (``/safety/disturbance_estimate``).
"""

from __future__ import annotations

import dataclasses
import enum
import math

import numpy as np

from rrtq_common.settings import check, setting

from .regression import FieldStatistics

__all__ = ['Bounds', 'FieldEstimate', 'LearnedBoundConfig', 'LegData', 'ModelFrame']

Bounds = tuple[tuple[float, float], tuple[float, float]]


class ModelFrame(enum.StrEnum):
    """Where the observer's one-step model is time-invariant (the rover's spring anchor)."""

    LEG_TARGET = 'leg_target'
    """x̄ relative to the current leg's target at rest."""
    WORLD_ORIGIN = 'world_origin'
    """x̄ = x."""


@dataclasses.dataclass(frozen=True)
class LearnedBoundConfig:
    """Parameters of ``learned_bound`` (each a :func:`rrtq_common.settings.setting`)."""

    region: Bounds = setting(unit='m', doc="((x_min, x_max), (y_min, y_max)): where the field "
                             "is learned (the scenario's bounds)")
    dt: float = setting(unit='s', low=0.0, low_open=True,
                        doc="the step of the loop (the controller's tau grid over a leg)")
    frame: ModelFrame = setting(ModelFrame.LEG_TARGET, doc='frame of the one-step model: '
                                'plant.spring_anchor (either without a spring)')
    confidence: float = setting(0.95, low=0.0, high=1.0, low_open=True, high_open=True,
                                doc='1 - delta of the simultaneous band (and of the noise '
                                'part of the tube)')
    window: int = setting(50, low=1, doc='legs of residual data the field is fitted on')
    feature_spacing: float = setting(
        2.0, unit='m', low=0.0, low_open=True,
        doc='spacing and length scale of the radial basis functions: at most the length '
        "scale of the field, or what they cannot fit leaks into the model's coefficients "
        '(docs/margins.md, section 4.2: at 4 m a 3 m bump softened the learned loop 3x)')
    ridge: float = setting(1.0, low=0.0, low_open=True,
                           doc='lambda of the regression (the features are of order 1)')
    prior_bound: float = setting(
        0.1, unit='m/s^2', low=0.0, low_open=True,
        doc='R: the field strength assumed possible before the data say otherwise (Jha\'s '
        'assumption 3.1); per component of the residual R dt on velocities, R dt^2/2 on '
        'positions')
    weight_bound: float = setting(1.5, low=0.0, low_open=True,
                                  doc="S_c = this x max(|w_c|, R_c): the bound of the field's "
                                  'weight norm the band assumes')
    noise_floor: float = setting(1e-5, low=0.0, low_open=True, doc='lower bound of the '
                                 'residual noise sigma_c, state units per step')
    cell: float = setting(1.0, unit='m', low=0.0, low_open=True,
                          doc="spacing of the cells the band's supremum is taken over")
    reach: float = setting(1.0, unit='m', low=0.0, low_open=True,
                           doc='a cell counts as visited when a residual was taken within '
                           'this distance')
    support: float = setting(
        0.5, low=0.0, low_open=True,
        doc="the band's supremum is taken over the visited cells within twice the longest "
        'leg of the window (at least twice feature_spacing) of the robot where the data have '
        "cut the band's width to at most this fraction of the prior's: where the next legs "
        'go and the data say something; elsewhere the bound is extrapolated, and a residual '
        'above it raises it at once (docs/margins.md, section 3)')
    bank_ratio: float = setting(0.8, doc='ratio of neighbouring levels of the bank')
    noise_allowance: float = setting(4.0, doc='a residual raises the bank when a component '
                                     'exceeds its bound by this many sigma_i')
    model_prior_precision: float = setting(1e-6, low=0.0, low_open=True,
                                           doc="mu: precision of the model's prior Phi = I, "
                                           'Gamma = 0 (negligible against a leg of data)')
    evaluation_period: float = setting(2.0, unit='s', low=0.0, low_open=True,
                                       doc='between fits within a leg (a fit also ends every '
                                       'leg)')
    recent_legs: int = setting(10, low=1, doc='leg starts (the last ones, the current '
                               'included) replayed through the current closed loop for the '
                               'nominal part: how the robot enters its legs now, not during '
                               'a transient')
    directions: int = setting(16, doc="directions of a leg's normal the tube is maximised over")
    robot_radius: float = setting(0.5, unit='m', low=0.0, doc='an obstacle within this of the '
                                  "current leg's corridor is grown by that leg's margin")
    hold_steps: int = setting(40, low=1, doc='steps the rest of a leg is bounded over at least '
                              'when a fit within it re-anchors the tube')

    def __post_init__(self) -> None:
        check(self, finite=True)


@dataclasses.dataclass(frozen=True)
class FieldEstimate:
    """The last fit's field and band on the policy's cells (``/safety/disturbance_estimate``).

    Accelerations (m/s²): the residual's velocity rows divided by dt. Cell k is at
    ``cells[k]``, on a grid of ``shape`` (nx, ny) from ``origin`` at ``spacing``, k = i ny + j.
    """

    t: float
    """s, when the fit was made."""
    origin: tuple[float, float]
    spacing: float
    shape: tuple[int, int]
    mean: np.ndarray
    """(cells, 2): the fitted field."""
    band: np.ndarray
    """(cells, 2): half-width of the simultaneous band."""
    supported: np.ndarray
    """(cells,): visited within reach, band cut to at most ``support`` of the prior's."""
    bound: float
    """m/s², the bank's level as an acceleration."""
    confidence: float
    samples: int


class LegData:
    """One leg's samples: statistics for the joint fit, visited cells, probing moments."""

    def __init__(self, p: int, n: int, d: int, cells: int) -> None:
        self.stats = FieldStatistics.zeros(p, n, d)
        self.visited = np.zeros(cells, dtype=bool)
        self.probing = np.zeros(3)            # Σ‖p‖², Σ p_k·p_{k−1}, pairs
        self._last_probe: np.ndarray | None = None
        self.samples: list[tuple[np.ndarray, np.ndarray, int]] = []
        """(z, y, cell) of the leg's samples past its first steps: residuals are recomputed
        against every new fit (docs/margins.md §5.1)."""

    @property
    def count(self) -> int:
        return self.stats.count

    def add_probing(self, p: np.ndarray) -> None:
        lag = 0.0 if self._last_probe is None else float(p @ self._last_probe)
        self.probing += (float(p @ p), lag, float(self._last_probe is not None))
        self._last_probe = p.copy()

    def probing_statistics(self, m: int) -> tuple[float, float]:
        """(stationary std per component, N; lag-one correlation) of the leg's probing."""
        sq, lag, pairs = self.probing
        if pairs < 2 or sq <= 0.0:
            return 0.0, 0.0
        steps = pairs + 1
        return math.sqrt(sq / (steps * m)), min(max(lag / sq * steps / pairs, 0.0), 0.999)
