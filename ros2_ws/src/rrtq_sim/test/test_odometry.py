"""The odometry noise: seeded and repeatable, white, with the stated standard deviations.

The statistical checks are tests of the hypothesis "the residuals are independent
N(0, σ²)" at a false-alarm rate of ALPHA = 1e-6 each (the exact χ² and normal quantiles,
not a tolerance picked to pass): a correct generator fails one of the five checks with
probability below 5e-6 whatever the seed. A wrong scale is caught: with 2 x 5000 samples
per quantity the χ² acceptance band is about ±7 % of the variance, and σ² in place of σ,
or one axis left exact, is far outside it.
"""

import numpy as np
import pytest
from scipy import stats

from rrtq_sim.odometry import ODOMETRY_STREAM, OdometryNoise, OdometryNoiseConfig, odometry_rng

ALPHA = 1e-6
STEPS = 5000
SIGMA_P, SIGMA_V = 0.3, 0.05


def residuals(seed, steps=STEPS, sigma_p=SIGMA_P, sigma_v=SIGMA_V):
    """(steps, 4) measurement minus state along a moving state, and the noise."""
    noise = OdometryNoise(OdometryNoiseConfig(position_std=sigma_p, velocity_std=sigma_v),
                          odometry_rng(seed))
    t = np.arange(steps) * 0.05
    states = np.column_stack([3.0 * np.cos(t), 2.0 * t, -3.0 * np.sin(t), np.full(steps, 2.0)])
    return np.array([noise.measure(x) for x in states]) - states, noise


def test_the_same_seed_measures_the_same_noise_and_another_seed_other_noise():
    a, _ = residuals(7, steps=50)
    b, _ = residuals(7, steps=50)
    c, _ = residuals(8, steps=50)
    assert np.array_equal(a, b)
    assert not np.any(a == c)


def test_the_noise_stream_is_not_the_runs_other_generators():
    # The disturbance injector and the controller draw from default_rng(seed): the
    # odometry noise must not repeat their draws.
    ours = odometry_rng(7).standard_normal(8)
    theirs = np.random.default_rng(7).standard_normal(8)
    assert not np.any(np.isclose(ours, theirs))
    assert np.array_equal(ours, np.random.default_rng([7, ODOMETRY_STREAM]).standard_normal(8))


def _variance_check(z):
    """z: standardised residuals; the χ² statistic of Σz² inside its two-sided band."""
    df = z.size
    statistic = float(np.sum(z ** 2))
    low, high = stats.chi2.ppf(ALPHA / 2, df), stats.chi2.ppf(1 - ALPHA / 2, df)
    return low <= statistic <= high, statistic / df


@pytest.mark.parametrize('seed', [0, 1, 12345])
def test_residuals_are_white_with_the_stated_deviations(seed):
    r, _ = residuals(seed)
    z = r / np.array([SIGMA_P, SIGMA_P, SIGMA_V, SIGMA_V])
    critical = stats.norm.ppf(1 - ALPHA / 2)
    for name, cols in (('position', [0, 1]), ('velocity', [2, 3])):
        ok, ratio = _variance_check(z[:, cols])
        assert ok, f'{name}: variance {ratio:.4f} x the stated one'
        mean_z = float(z[:, cols].sum() / np.sqrt(z[:, cols].size))
        assert abs(mean_z) <= critical, f'{name}: mean {mean_z:.2f} standard errors from 0'
    # Independent across axes, across position and velocity, and from step to step: each
    # sample correlation times sqrt(n) is N(0, 1) under independence.
    pairs = [(z[:, 0], z[:, 1]), (z[:, 2], z[:, 3]), (z[:, 0], z[:, 2]),
             (z[:-1, 0], z[1:, 0]), (z[:-1, 3], z[1:, 3])]
    for a, b in pairs:
        rho = float(np.corrcoef(a, b)[0, 1])
        assert abs(rho) * np.sqrt(a.size) <= critical, rho


def test_the_variance_check_tells_a_wrong_scale():
    # The check itself has power: the residuals judged against sigma^2 or 2 sigma fail.
    r, _ = residuals(3)
    for wrong in (SIGMA_P ** 2, 2 * SIGMA_P, 0.93 * SIGMA_P):
        assert not _variance_check(r[:, :2] / wrong)[0], wrong


def test_the_covariance_is_the_stated_variance():
    _, noise = residuals(0, steps=1)
    assert noise.position_variance == pytest.approx(SIGMA_P ** 2)
    assert noise.velocity_variance == pytest.approx(SIGMA_V ** 2)


def test_without_noise_the_measurement_is_the_state_bit_for_bit_and_draws_nothing():
    rng = odometry_rng(5)
    before = rng.bit_generator.state
    noise = OdometryNoise(OdometryNoiseConfig(), rng)
    x = np.array([-0.0, 1e-300, 3.25, -7.5, 99.0])        # n = 5: only the first four
    measured = noise.measure(x)
    assert noise.exact and measured.tobytes() == x[:4].tobytes()
    assert rng.bit_generator.state == before
    assert noise.position_variance == noise.velocity_variance == 0.0


def test_a_negative_deviation_is_refused():
    with pytest.raises(ValueError, match='position_std'):
        OdometryNoiseConfig(position_std=-0.1)
    with pytest.raises(ValueError, match='velocity_std'):
        OdometryNoiseConfig(velocity_std=float('nan'))
