"""The residual field's regression on synthetic data with a known field and known noise:
simultaneous coverage, the paper's pointwise band for contrast, narrowing with data, a bump
outside the feature span, and the joint fit of a one-step model of a true plant."""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from rrtq_planner.margins.coverage import binomial_interval
from rrtq_planner.margins.observer import OneStepModel
from rrtq_planner.margins.regression import FieldStatistics, RBFFeatures, fit_field
from rrtq_sim.field import Bump, DisturbanceField, compose_input_matrix
from rrtq_sim.plant import Plant, rover_matrices

BOX = ((0.0, 12.0), (0.0, 12.0))
FEATURES = RBFFeatures(BOX, 3.0)
_G = np.linspace(0.0, 12.0, 37)
GRID = np.array(np.meshgrid(_G, _G, indexing='ij')).reshape(2, -1).T
GRID_PHI = FEATURES(GRID)
DELTA = 0.05


def walks(rng, reps, n, speed=0.15):
    """Smooth random paths reflected into the box, (reps, n, 2): data gathered along a
    trajectory, as a robot gathers them (each position depends on the last)."""
    v = lfilter([1.0], [1.0, -0.97], rng.standard_normal((reps, n, 2)), axis=1)
    x = 6.0 + speed * np.cumsum(v, axis=1) + rng.uniform(-4, 4, (reps, 1, 2))
    period = 24.0
    return 12.0 - np.abs(np.mod(x, period) - 12.0)


def fit(phi, y, noise, bound):
    stats = FieldStatistics(phi.T @ phi, (phi.T @ y)[:, None], np.array([y @ y]), len(y))
    return fit_field(stats, 1.0, DELTA, bound, noise=noise)


def test_band_is_simultaneous_over_the_region_and_the_pointwise_band_is_not():
    # d = φᵀw* with ‖w*‖ = S, Gaussian noise σ, 300 repetitions: the whole band covers d on
    # every grid point of the region in at least 1 − δ of them (lower end of a 95 %
    # Clopper-Pearson interval); Jha's eq. 9 band, pointwise, does not.
    rng = np.random.default_rng(0)
    reps, n, sigma, S = 300, 600, 0.2, 1.0
    paths = walks(rng, reps, n)
    both = np.zeros(reps, dtype=bool)
    point = np.zeros(reps, dtype=bool)
    for r in range(reps):
        w = rng.standard_normal(FEATURES.size)
        w *= S / np.linalg.norm(w)
        phi = FEATURES(paths[r])
        f = fit(phi, phi @ w + sigma * rng.standard_normal(n), sigma, S)
        truth = GRID_PHI @ w
        mean, half = f.band(GRID_PHI)
        both[r] = np.all(np.abs(mean[:, 0] - truth) <= half[:, 0])
        centre, phalf = f.pointwise_band(GRID_PHI, DELTA)
        point[r] = np.all(np.abs(centre[:, 0] - truth) <= phalf[:, 0])
    assert binomial_interval(int(both.sum()), reps)[0] >= 1 - DELTA
    assert binomial_interval(int(point.sum()), reps)[1] < 1 - DELTA


def test_band_narrows_as_data_grow():
    rng = np.random.default_rng(1)
    reps, sigma, S = 20, 0.2, 1.0
    paths = walks(rng, reps, 3200)
    widths = np.zeros((reps, 3))
    for r in range(reps):
        w = rng.standard_normal(FEATURES.size)
        w *= S / np.linalg.norm(w)
        # The cells the first 200 samples passed near: the same region for every n.
        near = np.min(np.linalg.norm(GRID[:, None] - paths[r, None, :200], axis=2), axis=1) < 1.0
        for i, n in enumerate((200, 800, 3200)):
            phi = FEATURES(paths[r, :n])
            f = fit(phi, phi @ w + sigma * rng.standard_normal(n), sigma, S)
            widths[r, i] = f.band(GRID_PHI[near])[1].mean()
    mean = widths.mean(axis=0)
    assert mean[0] > mean[1] > mean[2]
    assert mean[2] < 0.6 * mean[0]
    assert np.all(widths[:, 2] < widths[:, 0])


def test_a_bump_outside_the_feature_span_is_learned_within_the_band():
    # The field is a smooth bump (not a sum of the features); with enough passes over it
    # the mean is within the band of the true value around its centre.
    rng = np.random.default_rng(2)
    field = DisturbanceField([Bump((6.0, 6.0), 4.0, (1.0, 0.0))])
    reps, n, sigma = 200, 2000, 0.1
    paths = walks(rng, reps, n)
    inner = np.linalg.norm(GRID - 6.0, axis=1) <= 2.0
    truth = field.acceleration(GRID[inner])[:, 0]
    covered = np.zeros(reps, dtype=bool)
    for r in range(reps):
        phi = FEATURES(paths[r])
        y = field.acceleration(paths[r])[:, 0] + sigma * rng.standard_normal(n)
        f = fit(phi, y, sigma, 3.0)
        mean, half = f.band(GRID_PHI[inner])
        covered[r] = np.all(np.abs(mean[:, 0] - truth) <= half[:, 0])
        assert np.abs(mean[:, 0] - truth).max() < 0.25        # learned, not just covered
    assert binomial_interval(int(covered.sum()), reps)[0] >= 1 - DELTA


def test_joint_fit_recovers_the_plant_where_a_two_stage_fit_absorbs_the_field():
    # A true rover (no spring) driven leg by leg to random targets through a field bump, the
    # model in the legs' frame (x̄ = x − x_r), the field on the world position: fitted jointly
    # the one-step model is the plant's ZOH discretisation and the field's band covers the
    # true residual Γ_d a(p); the recursive least-squares model fitted alone (the two-stage
    # way) soaks part of the field into Φ̂.
    a_mat, b_mat = rover_matrices(40.0, 0.0, 45.0)
    dt = 0.05
    plant = Plant(a_mat, b_mat, compose_input_matrix(None, 4), dt, 1000.0)
    field = DisturbanceField([Bump((6.0, 6.0), 5.0, (0.4, -0.3))])
    rng = np.random.default_rng(4)
    steps, leg = 6000, 100
    probe = 20.0 * lfilter([0.1], [1.0, -0.9], rng.standard_normal((steps, 2)), axis=0)
    targets = rng.uniform(1.0, 11.0, (steps // leg, 2))
    x = np.array([6.0, 6.0, 0.0, 0.0])
    stats = FieldStatistics.zeros(FEATURES.size, 4, 6)
    rls = OneStepModel(4, 2)
    visited = []
    for k in range(steps):
        xr = np.concatenate([targets[k // leg], np.zeros(2)])
        u = probe[k] - [40.0, 40.0, 30.0, 30.0] * (x - xr) @ np.array(
            [[1, 0], [0, 1], [1, 0], [0, 1]])
        x1 = plant.step(x, u, field.acceleration(x), np.zeros(2))
        z = np.concatenate([x - xr, u])
        stats.add(FEATURES(x[:2]), x1 - xr, z)
        rls.update(z, x1 - xr)
        visited.append(x[:2].copy())
        x = x1
    prior = (np.hstack([np.eye(4), np.zeros((4, 2))]), 1e-6)
    f = fit_field(stats, 1.0, DELTA, 3.0 * 0.4 * dt, 1e-6, model_prior=prior)
    joint_err = np.abs(f.model[:, :4] - plant.phi).max()
    rls_err = np.abs(rls.phi - plant.phi).max()
    assert joint_err < 1e-3
    assert np.abs(f.model[:, 4:] - plant.gamma_u).max() < 3e-5       # Γ ≈ 1.2e-3
    assert rls_err > 5 * joint_err
    pts = np.array(visited)
    near = np.min(np.linalg.norm(GRID[:, None] - pts[None, ::20], axis=2), axis=1) < 1.0
    truth = field.acceleration(GRID[near]) @ plant.gamma_d.T
    mean, half = f.band(GRID_PHI[near])
    assert np.all(np.abs(mean - truth) <= half)
    assert np.abs(mean[:, 2:] - truth[:, 2:]).max() < 0.35 * 0.4 * dt     # learned, not just covered


def test_rls_is_exact_on_noise_free_data():
    a_mat, b_mat = rover_matrices(40.0, 20.0, 45.0)
    plant = Plant(a_mat, b_mat, None, 0.05, 1000.0)
    rng = np.random.default_rng(5)
    model = OneStepModel(4, 2)
    x = np.zeros(4)
    for _ in range(300):
        u = rng.normal(0.0, 50.0, 2)
        x1 = plant.step(x, u, None, np.zeros(2))
        model.update(model.regressor(x, u), x1)
        x = x1
    np.testing.assert_allclose(model.phi, plant.phi, atol=1e-6)
    np.testing.assert_allclose(model.gamma, plant.gamma_u, atol=1e-8)
