"""The critic fit's noise part and spread: what the guard's tests use to tell noise from a wrong critic.

Synthetic Bellman rows with a known answer: rows σθ* + k = ε (a correct critic, θ*) with
white noise ε of any size, or with a slowly varying term the critic cannot represent (a
wrong one). The guard (``max_fit_residual``, 0.3) asks the misfit, the residual less its
noise part: a correct critic passes at any noise floor, where the plain relative residual
(the test before) rejects it; a wrong one fails at any noise floor.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from rrtq_controller.critic import SampleWindow, fit
from rrtq_controller.guard import FALSE_ALARM

N, P = 2000, 12


def _window() -> SampleWindow:
    window = SampleWindow(N, 4, 2, 0)
    for k in range(N):                         # in time order, 0.05 s apart
        window.add_sample(10.0, np.zeros(4), 9.95, np.zeros(4), np.zeros(2), np.zeros(0), k)
    return window


def _rows(noise: float, wrong: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    t = 0.05 * np.arange(N)
    # regressors that vary along the trajectory, as σ of the Bellman rows do (slowly)
    sig = np.column_stack([np.sin(0.3 * (i + 1) * t + i) for i in range(P)]) + 0.3 * rng.standard_normal((N, P))
    theta = rng.normal(size=P)
    y = sig @ theta
    y_true_scale = float(np.std(y))
    smooth = wrong * y_true_scale * np.sin(2 * np.pi * t / 7.3) ** 3     # no σ represents it
    k = -(y + smooth + noise * y_true_scale * rng.standard_normal(N))

    def rows(*_batch):
        return sig, k, np.zeros((0, P)), np.zeros(0)
    return rows, theta


@pytest.mark.parametrize('noise', [0.1, 0.4, 1.0])
def test_a_correct_critic_passes_at_any_noise_floor(noise):
    rows, theta = _rows(noise, wrong=0.0)
    f = fit(rows, _window(), np.zeros(P), 1e-9)
    assert np.abs(f.theta - theta).max() < 0.1 + 0.2 * noise      # least squares is consistent
    assert f.misfit < 0.3                                           # the guard passes it
    if noise >= 0.4:
        assert f.residual > 0.3                                     # the plain residual did not
    assert f.noise == pytest.approx(f.residual, rel=0.1)


@pytest.mark.parametrize('noise', [0.0, 0.4, 1.0])
def test_a_critic_that_cannot_represent_the_data_fails_at_any_noise_floor(noise):
    rows, _ = _rows(noise, wrong=1.5)
    f = fit(rows, _window(), np.zeros(P), 1e-9)
    assert f.misfit > 0.3


def test_the_spread_covers_the_estimation_error_at_its_stated_rate():
    """The standard error of gᵀθ̂ from :attr:`Fit.spread`: |gᵀ(θ̂ - θ*)| <= z σ on the stated share."""
    misses, trials = 0, 200
    z = norm.ppf(1.0 - FALSE_ALARM / 2)
    for seed in range(trials):
        rows, theta = _rows(0.5, wrong=0.0, seed=seed)
        f = fit(rows, _window(), np.zeros(P), 1e-9)
        g = np.random.default_rng(1000 + seed).normal(size=(1, P))
        error = float(g[0] @ (f.theta - theta))
        misses += abs(error) > z * float(f.standard_errors(g)[0])
    # binomial: at most α of the trials, with 5 sigma of slack
    assert misses / trials <= FALSE_ALARM + 5 * np.sqrt(FALSE_ALARM / trials)
