"""Disturbance signals d(t) applied to the plant through F."""

from __future__ import annotations

import enum
import math

import numpy as np
import numpy.typing as npt

from rrtq_sim.riccati import RiccatiSolution

__all__ = ['DisturbanceModel', 'DisturbanceGenerator']


class DisturbanceModel(enum.StrEnum):
    """Which signal the disturbance injector plays."""

    NONE = 'none'
    CONSTANT = 'constant'
    SINUSOID = 'sinusoid'
    GAUSSIAN = 'gaussian'
    WORST_CASE = 'worst_case'


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
    ) -> None:
        self._model = DisturbanceModel(model)
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
