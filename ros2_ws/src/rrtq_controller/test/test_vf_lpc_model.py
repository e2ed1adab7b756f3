"""VF-LPC's nominal model (EDMD with control) and online sparse GP, against outside truth.

Truth: the rover's zero-order-hold matrices from scipy's ``expm`` of the continuous
model, and batch FITC (Snelson & Ghahramani, eq. 7 of VF-LPC) written out here with
numpy on the same data.
"""

import numpy as np
import pytest

from rrtq_controller.vf_lpc import (LIFTINGS, KoopmanModel, OnlineSparseGP, SparseGPConfig,
                                    fit_edmd)
from rrtq_testing import controller_reference as ref

DT = 0.05


def rover_zoh(mass, damping=45.0):
    return ref.zoh(*ref.rover(mass, 0.0, damping), DT)


def probe(phi, gamma, steps, rng, offset=None):
    u = np.repeat(rng.uniform(-400, 400, (steps // 10 + 1, 2)), 10, axis=0)[:steps]
    x = np.zeros((steps + 1, 4))
    for k in range(steps):
        x[k + 1] = phi @ x[k] + gamma @ u[k] + (0.0 if offset is None else offset)
    return x[:-1], u, x[1:]


def test_edmd_recovers_the_zero_order_hold_matrices():
    phi, gamma = rover_zoh(40.0)
    x, u, xn = probe(phi, gamma, 400, np.random.default_rng(1))
    model = fit_edmd(x, u, xn, DT)
    assert np.allclose(model.A, phi, atol=1e-6) and np.allclose(model.B, gamma, atol=1e-8)
    pred = model.rollout(x[0], u[:40])
    assert np.abs(pred[-1] - xn[39]).max() < 1e-5


def test_affine_lifting_absorbs_a_constant_drift(tmp_path):
    phi, gamma = rover_zoh(40.0)
    drift = np.array([0.0, 0.0, 0.01, -0.02])        # a constant push, m/s per step
    x, u, xn = probe(phi, gamma, 400, np.random.default_rng(2), drift)
    linear = fit_edmd(x, u, xn, DT, 'linear')
    affine = fit_edmd(x, u, xn, DT, 'affine')
    assert np.allclose(affine.A[:4, 4], drift, atol=1e-6)
    err_lin = np.abs(xn - linear.step(x, u)).max()
    err_aff = np.abs(xn - affine.step(x, u)).max()
    assert err_aff < 1e-6 < err_lin
    affine.save(tmp_path / 'm.npz')
    back = KoopmanModel.load(tmp_path / 'm.npz')
    assert back.lifting is LIFTINGS['affine'] and np.array_equal(back.A, affine.A)


def test_model_file_errors_name_the_file(tmp_path):
    bad = tmp_path / 'bad.npz'
    np.savez(bad, A=np.eye(2))
    with pytest.raises(ValueError, match='bad.npz'):
        KoopmanModel.load(bad)


def f_true(z):
    return np.column_stack((np.sin(z[:, 0]) * np.cos(0.5 * z[:, 1]),
                            0.5 * z[:, 0] - np.tanh(z[:, 1])))


def gp_config(**kw):
    return SparseGPConfig(lengthscales=(1.0, 1.0), signal_std=(1.0, 1.0),
                          noise_std=(0.1, 0.1), **kw)


def test_gp_error_shrinks_and_two_sigma_covers_about_95_percent():
    rng = np.random.default_rng(0)
    gp = OnlineSparseGP(gp_config(max_dictionary=60, ald_threshold=0.05))
    test = rng.uniform(-3, 3, (2000, 2))
    errors, sizes = [], []
    for n in range(1, 1501):
        z = rng.uniform(-3, 3, 2)
        gp.update(z, f_true(z[None])[0] + rng.normal(0, 0.1, 2))
        sizes.append(gp.size)
        if n in (30, 300, 1500):
            mean, var = gp.predict(test)
            errors.append(np.sqrt(np.mean((mean - f_true(test)) ** 2)))
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.05
    assert max(sizes) <= 60
    # Coverage of new noisy observations by mean ± 2 sd (latent plus noise variance).
    y = f_true(test) + rng.normal(0, 0.1, test.shape)
    covered = np.abs(y - mean) <= 2.0 * np.sqrt(var + gp.noise_var)
    assert 0.93 <= covered.mean() <= 0.995


def test_full_dictionary_replaces_points_and_stays_bounded():
    rng = np.random.default_rng(3)
    gp = OnlineSparseGP(gp_config(max_dictionary=15, ald_threshold=0.2))

    def g(z):
        return np.column_stack((np.sin(z[:, 0]), np.cos(0.7 * z[:, 0]) + 0.5 * z[:, 1]))

    for x in np.linspace(-20, 20, 800):      # a sweep through new ground all the time
        z = np.array([x, np.sin(x)])
        gp.update(z, g(z[None])[0] + rng.normal(0, 0.1, 2))
        assert gp.size <= 15
    here = np.array([[19.5, np.sin(19.5)]])
    assert np.abs(gp.predict(here)[0] - g(here)).max() < 0.1
    far = np.array([[-19.5, np.sin(-19.5)]])  # forgotten: back to the prior
    assert gp.predict(far)[1].min() > 0.5


def test_online_posterior_equals_batch_fitc_on_a_fixed_dictionary():
    rng = np.random.default_rng(4)
    cfg = gp_config(max_dictionary=50, ald_threshold=0.3)
    gp = OnlineSparseGP(cfg)
    grid = np.array([[a, b] for a in np.linspace(-3, 3, 5) for b in np.linspace(-3, 3, 5)])
    data_z, data_y = [], []
    for z in grid:                            # the dictionary: every grid point joins
        y = f_true(z[None])[0] + rng.normal(0, 0.1, 2)
        assert gp.update(z, y)
        data_z.append(z)
        data_y.append(y)
    near = grid[rng.integers(0, len(grid), 300)] + rng.uniform(-0.2, 0.2, (300, 2))
    for z in near:                            # each close to a dictionary point: none joins
        y = f_true(z[None])[0] + rng.normal(0, 0.1, 2)
        assert not gp.update(z, y)
        data_z.append(z)
        data_y.append(y)
    Z, Y = np.array(data_z), np.array(data_y)

    def k(a, b):
        return np.exp(-0.5 * ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1))

    kuu = k(grid, grid) + 1e-10 * np.eye(len(grid))
    kuf = k(grid, Z)
    qff = np.einsum('uf,uv,vf->f', kuf, np.linalg.inv(kuu), kuf)
    lam = 1.0 - qff + 0.01                    # diag(K_ff - Q_ff) + sigma²
    sigma = np.linalg.inv(kuu + (kuf / lam) @ kuf.T)
    test = rng.uniform(-2, 2, (50, 2))
    ks = k(test, grid)
    mean_batch = ks @ sigma @ (kuf / lam) @ Y
    var_batch = 1.0 - np.einsum('nu,uv,nv->n', ks, np.linalg.inv(kuu) - sigma, ks)
    mean, var = gp.predict(test)
    assert np.allclose(mean, mean_batch, atol=1e-6)
    assert np.allclose(var, var_batch[:, None], atol=1e-6)


def test_mean_jacobian_matches_finite_differences():
    rng = np.random.default_rng(5)
    gp = OnlineSparseGP(gp_config())
    for z in rng.uniform(-2, 2, (100, 2)):
        gp.update(z, f_true(z[None])[0])
    at = rng.uniform(-2, 2, (5, 2))
    _, jac = gp.mean_and_jacobian(at)
    eps = 1e-6
    fd = np.stack([(gp.predict(at + eps * e)[0] - gp.predict(at - eps * e)[0]) / (2 * eps)
                   for e in np.eye(2)], axis=-1)
    assert np.allclose(jac, fd, atol=1e-6)
