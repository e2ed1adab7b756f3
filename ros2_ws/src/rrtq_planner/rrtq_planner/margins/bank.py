"""The ordered bank of disturbance bounds of Jha's Algorithm 1 (``docs/margins.md`` §3).

Jha keeps E_k = {R > r_1 > r_2 > ...}, a value function per bound, and plays the one of the
smallest bound the current estimate allows. A margin's "value function" is the tube of
:mod:`.tube`, which is linear in the bound, so the bank only has to hold the levels: a
geometric ladder ratioⁱ (i an integer, any scale), above it +inf (no bound yet: the
conservative start). The active level

* moves to the smallest level at least the band's supremum r_k at each evaluation (down only
  when the band allows it; up when the band has widened);
* moves up at once when a residual exceeds the active level (plus the noise allowance the
  caller adds), to the smallest level at least that residual; this is counted.

Quantising to a ladder keeps the published margin, and with it the planner's obstacle set,
from changing at every evaluation.
"""

from __future__ import annotations

import math

__all__ = ['BoundBank']


class BoundBank:
    """Active level of a geometric ladder of bounds.

    Parameters
    ----------
    ratio
        Ratio of neighbouring levels, in (0, 1).
    """

    def __init__(self, ratio: float = 0.8) -> None:
        if not 0.0 < ratio < 1.0:
            raise ValueError(f'ratio must be in (0, 1), got {ratio!r}')
        self.ratio = float(ratio)
        self._log_ratio = math.log(ratio)
        self.level = math.inf
        self.steps_down = 0
        self.steps_up = 0
        self.violations = 0

    def ceil(self, value: float) -> float:
        """The smallest level >= ``value`` (inf stays inf; 0 and below give 0)."""
        if value <= 0.0:
            return 0.0
        if math.isinf(value):
            return math.inf
        i = math.floor(math.log(value) / self._log_ratio + 1e-9)   # ratio^i >= value
        level = self.ratio ** i
        return level if level >= value else self.ratio ** (i - 1)

    def evaluate(self, supremum: float) -> float:
        """Follow the band: the active level becomes ceil(sup of its upper band)."""
        new = self.ceil(supremum)
        self.steps_down += new < self.level
        self.steps_up += new > self.level
        self.level = new
        return self.level

    def observe(self, residual: float) -> bool:
        """A residual (already net of the noise allowance) above the level raises it at once."""
        if residual <= self.level:
            return False
        self.level = self.ceil(residual)
        self.steps_up += 1
        self.violations += 1
        return True
