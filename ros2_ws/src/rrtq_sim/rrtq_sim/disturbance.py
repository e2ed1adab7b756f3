"""Disturbance signals d(t) applied to the plant through F."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.settings import check, setting
from rrtq_sim.field import Bump, DisturbanceField
from rrtq_sim.riccati import RiccatiSolution, solve_riccati

__all__ = ['DisturbanceModel', 'DisturbanceConfig', 'WorstCaseGame', 'DisturbanceGenerator',
           'make_generator']


def _maxwell_slip() -> np.ndarray:
    """The paper's Maxwell-slip disturbance column F = [0, 0, -1, 1]^T (4 states)."""
    f = np.array([[0.0], [0.0], [-1.0], [1.0]])
    f.setflags(write=False)
    return f


class DisturbanceModel(enum.StrEnum):
    """Which signal the disturbance injector plays."""

    NONE = 'none'
    CONSTANT = 'constant'
    SINUSOID = 'sinusoid'
    GAUSSIAN = 'gaussian'
    WORST_CASE = 'worst_case'
    FIELD = 'field'
    """A position-dependent acceleration (:mod:`rrtq_sim.field`), F = [0; I2]."""


@dataclass(frozen=True, eq=False, kw_only=True)
class DisturbanceConfig:
    """The disturbance d(t) applied through F."""

    model: DisturbanceModel = setting(DisturbanceModel.NONE, doc='the signal')
    F: np.ndarray = setting(factory=_maxwell_slip, rows='n',
                            doc='disturbance matrix F (n x q); default: the Maxwell-slip column')
    amplitude: float = setting(1.0, doc='constant: the value; sinusoid: the amplitude; '
                               'gaussian: the std; worst_case: the clip (units of d)')
    frequency: float = setting(0.2, unit='Hz', low=0.0, doc='sinusoid frequency')
    gamma: float | None = setting(None, low=0.0, low_open=True,
                                  doc='worst_case: attenuation level of the game that defines d*')
    bumps: tuple[tuple[float, ...], ...] = setting(
        (), columns=5, doc='field: one row [center x, center y, radius, a_x, a_y] per bump '
        '(m, m, m, m/s^2, m/s^2)')

    def __post_init__(self) -> None:
        check(self)

    @property
    def q(self) -> int:
        """Disturbance dimension."""
        return int(self.F.shape[1])

    def field(self) -> DisturbanceField:
        """The bumps as a :class:`rrtq_sim.field.DisturbanceField`."""
        return DisturbanceField([Bump((row[0], row[1]), row[2], (row[3], row[4]))
                                 for row in self.bumps])


@dataclass(frozen=True, eq=False, kw_only=True)
class WorstCaseGame:
    """The zero-sum game the worst-case disturbance plays.

    The true plant, the controller's cost weights and horizon (no defaults: the
    orchestrator hands them over).
    """

    A: np.ndarray = setting(rows='n', doc='true state matrix A (n x n)')
    B: np.ndarray = setting(rows='n', doc='true input matrix B (n x m)')
    M: np.ndarray = setting(rows='n', doc="controller's state weight M (n x n)")
    R: np.ndarray = setting(rows='m', doc="controller's control weight R (m x m)")
    P_T: np.ndarray = setting(rows='n', doc="controller's terminal weight P(T) (n x n)")
    horizon: float = setting(unit='s', low=0.0, low_open=True, doc='leg horizon T')

    def riccati(self, F: npt.ArrayLike, gamma: float) -> RiccatiSolution:
        """The game Riccati solution P(τ) over one leg (robust paper eq. 8)."""
        return solve_riccati(self.A, self.B, self.M, self.R, self.P_T, self.horizon,
                             F=F, gamma=gamma)


class DisturbanceGenerator:
    """Produce the disturbance vector d for the current time and state.

    Parameters
    ----------
    model : DisturbanceModel
        The signal.
    q : int
        Disturbance dimension (columns of F).
    amplitude : float
        constant: the value; sinusoid: the amplitude; gaussian: the standard
        deviation; worst_case: the elementwise clip, all in the units of d.
    frequency : float
        Sinusoid frequency, Hz.
    rng : numpy.random.Generator
        Source of the Gaussian draws (the node owns and seeds it).
    riccati : RiccatiSolution, optional
        Game Riccati solution; required for ``WORST_CASE``.
    F : array_like, shape (n, q), optional
        Disturbance matrix for ``WORST_CASE``; defaults to ``riccati.F``.
    gamma : float, optional
        Attenuation level for ``WORST_CASE``; defaults to ``riccati.gamma``.
    field : DisturbanceField, optional
        The acceleration field for ``FIELD`` (d = a(p), q = 2).
    """

    def __init__(
        self,
        model: DisturbanceModel,
        q: int,
        amplitude: float,
        frequency: float,
        rng: np.random.Generator,
        riccati: RiccatiSolution | None = None,
        F: npt.ArrayLike | None = None,
        gamma: float | None = None,
        field: DisturbanceField | None = None,
    ) -> None:
        self._model = DisturbanceModel(model)
        if self._model is DisturbanceModel.FIELD and field is None:
            raise ValueError('field needs its bumps')
        self._field = field
        if q < 0:
            raise ValueError(f'q must be >= 0, got {q}')
        if not math.isfinite(amplitude):
            raise ValueError(f'amplitude must be finite, got {amplitude!r}')
        clip_or_std = (DisturbanceModel.GAUSSIAN, DisturbanceModel.WORST_CASE)
        if self._model in clip_or_std and amplitude < 0.0:
            raise ValueError(
                f'amplitude is a std/clip for {self._model}: must be >= 0, got {amplitude!r}'
            )
        if not (math.isfinite(frequency) and frequency >= 0.0):
            raise ValueError(f'frequency must be finite and >= 0, got {frequency!r}')
        self._q = int(q)
        self._amplitude = float(amplitude)
        self._frequency = float(frequency)
        self._rng = rng
        self._riccati = riccati
        self._gain_matrix: np.ndarray | None = None
        if self._model is DisturbanceModel.WORST_CASE:
            if riccati is None:
                raise ValueError('worst_case needs a Riccati solution')
            f = riccati.F if F is None else np.array(F, dtype=float, ndmin=2)
            g = riccati.gamma if gamma is None else float(gamma)
            if f is None or g is None:
                raise ValueError(
                    'worst_case needs F and gamma (given or from the game Riccati solution)'
                )
            if f.shape != (riccati.n, self._q):
                raise ValueError(f'F must have shape ({riccati.n}, {self._q}), got {f.shape}')
            if not (math.isfinite(g) and g > 0.0):
                raise ValueError(f'gamma must be finite and > 0, got {g!r}')
            self._gain_matrix = f.T / g**2

    @property
    def model(self) -> DisturbanceModel:
        """The signal being played."""
        return self._model

    @property
    def q(self) -> int:
        """Disturbance dimension."""
        return self._q

    def value(self, t: float, xbar: npt.ArrayLike, tau: float) -> np.ndarray:
        """Return d at simulated time ``t``.

        Parameters
        ----------
        t : float
            Simulated time, s.
        xbar : array_like, shape (n,)
            State relative to the current leg's target (worst_case only).
        tau : float
            Time-to-go on the current leg, s (worst_case only).

        Returns
        -------
        numpy.ndarray, shape (q,)
        """
        model = self._model
        if model is DisturbanceModel.NONE:
            return np.zeros(self._q)
        if model is DisturbanceModel.FIELD:
            raise ValueError('the field depends on the position: use value_at')
        if model is DisturbanceModel.CONSTANT:
            return np.full(self._q, self._amplitude)
        if model is DisturbanceModel.SINUSOID:
            phase = 2.0 * math.pi * self._frequency * t
            return np.full(self._q, self._amplitude * math.sin(phase))
        if model is DisturbanceModel.GAUSSIAN:
            # Exactly one draw of size q per call keeps a seeded run repeatable.
            return self._rng.normal(0.0, self._amplitude, self._q)
        assert self._riccati is not None and self._gain_matrix is not None
        x = np.asarray(xbar, dtype=float).reshape(-1)
        if x.shape != (self._riccati.n,):
            raise ValueError(f'xbar must have shape ({self._riccati.n},), got {np.shape(xbar)}')
        # d* = gamma^-2 F^T P(tau) x_bar (robust paper eq. 10); the clip keeps the
        # adversary physically plausible.
        d = self._gain_matrix @ (self._riccati.P(tau) @ x)
        return np.clip(d, -self._amplitude, self._amplitude)

    def value_at(self, t: float, x: npt.ArrayLike, target: npt.ArrayLike | None,
                 tau: float) -> np.ndarray:
        """The disturbance at ``t`` for the full state ``x`` on a leg to ``target`` (m, at rest).

        The game's state is relative to the leg's target held at rest: its position is
        subtracted from the first two components. Without a leg (``target`` None) the
        state is taken as it is, with ``tau``.
        """
        xbar = np.array(x, dtype=float).reshape(-1)
        if self._field is not None:
            # The field acts where the robot is, held over the step like u (field.py).
            return np.asarray(self._field.acceleration(xbar[:2]), dtype=float)
        if target is not None:
            xbar[:2] -= np.asarray(target, dtype=float)
        return self.value(t, xbar, tau)


def make_generator(config: DisturbanceConfig, rng: np.random.Generator,
                   game: WorstCaseGame | None = None) -> DisturbanceGenerator:
    """The generator of ``config`` (worst_case: of ``game`` at ``config.gamma``)."""
    riccati = None
    if config.model is DisturbanceModel.WORST_CASE:
        if game is None or config.gamma is None:
            raise ValueError('worst_case needs the game and gamma')
        riccati = game.riccati(config.F, config.gamma)
    field = config.field() if config.model is DisturbanceModel.FIELD else None
    return DisturbanceGenerator(config.model, config.q, config.amplitude, config.frequency, rng,
                                riccati=riccati, F=config.F, gamma=config.gamma, field=field)
