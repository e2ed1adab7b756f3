"""Open-loop force player: a scripted, piecewise-constant force profile (no learning).

Drives the plant before (or without) the learning controller: docs/design.md's
``controller: {variant: open_loop, forces: [[t0, fx, fy], ...]}``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np


@dataclasses.dataclass(frozen=True)
class ForceProfile:
    """Forces (N) held from each time (s) until the next; zero before the first."""

    times: np.ndarray     # (K,) s, strictly increasing
    forces: np.ndarray    # (K, m) N

    @classmethod
    def from_rows(cls, rows: Sequence[Sequence[float]] | np.ndarray) -> ForceProfile:
        table = np.asarray(rows, dtype=float).reshape(-1, 3)
        if table.size and np.any(np.diff(table[:, 0]) <= 0):
            raise ValueError('force profile times must be strictly increasing')
        return cls(times=table[:, 0].copy(), forces=table[:, 1:].copy())

    def force_at(self, t: float) -> np.ndarray:
        """u(t): the row of the last time <= t (a tiny tolerance absorbs stamp round-off)."""
        i = int(np.searchsorted(self.times, t + 1e-9, side='right')) - 1
        if i < 0:
            return np.zeros(self.forces.shape[1] if self.forces.size else 2)
        return self.forces[i].copy()
