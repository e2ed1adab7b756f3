"""Binomial (Clopper-Pearson) intervals for coverage and violation rates."""

from __future__ import annotations

from scipy.stats import beta

__all__ = ['binomial_interval']


def binomial_interval(successes: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """The exact two-sided Clopper-Pearson interval of a binomial proportion.

    Parameters
    ----------
    successes, trials
        Counts (0 <= successes <= trials, trials >= 1).
    confidence
        Coverage of the interval itself (not the margin's 1 − δ).

    Returns
    -------
    (low, high)
        Bounds of the proportion; each tail holds (1 − confidence) / 2.
    """
    if trials < 1 or not 0 <= successes <= trials:
        raise ValueError(f'need 0 <= successes <= trials >= 1, got {successes}/{trials}')
    tail = 0.5 * (1.0 - confidence)
    low = 0.0 if successes == 0 else float(beta.ppf(tail, successes, trials - successes + 1))
    high = 1.0 if successes == trials else float(beta.ppf(1.0 - tail, successes + 1,
                                                          trials - successes))
    return low, high
