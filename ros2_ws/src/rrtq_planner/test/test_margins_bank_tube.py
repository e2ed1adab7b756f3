"""The bank of bounds (Alg. 1's rules) and the closed-loop tube against direct simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_planner.margins.bank import BoundBank
from rrtq_planner.margins.tube import (closed_loop, expanding, leg_tube_terms,
                                       nominal_deviation, nominal_path, random_deviation,
                                       tube_gains)
from rrtq_testing import controller_reference as ref


def test_bank_steps_down_only_when_the_band_allows_and_up_at_once():
    rng = np.random.default_rng(0)
    bank = BoundBank(0.8)
    assert bank.level == math.inf
    for _ in range(2000):
        before = bank.level
        if rng.random() < 0.3:
            sup = float(rng.lognormal(0.0, 1.0))
            bank.evaluate(sup)
            # The new level is a ladder level at least the band's supremum, the lowest one.
            assert bank.level >= sup and bank.level * 0.8 < sup
            i = math.log(bank.level) / math.log(0.8)
            assert abs(i - round(i)) < 1e-9
        else:
            residual = float(rng.lognormal(0.0, 1.0))
            raised = bank.observe(residual)
            assert raised == (residual > before)
            # A residual never lowers the level; one above it lifts it over the residual.
            assert bank.level >= before if not raised else bank.level >= residual
            if not raised:
                assert bank.level == before
    assert bank.ceil(0.0) == 0.0 and bank.ceil(math.inf) == math.inf


def _loop():
    """The rover without a spring under the finite-horizon Riccati gain of a 10 s leg."""
    a, b = ref.rover(40.0, 0.0, 45.0)
    dt, horizon = 0.05, 10.0
    plant = ref.Plant(a, b, dt)
    P = ref.riccati(a, b, 10.0 * np.eye(4), 0.02 * np.eye(2), 0.5 * np.eye(4), horizon)
    taus = horizon - dt * np.arange(int(horizon / dt))
    gains = np.stack([50.0 * b.T @ P(t) for t in taus])            # R⁻¹BᵀP(τ)
    return plant, gains


def test_tube_is_attained_by_the_worst_sequence_and_never_exceeded():
    plant, gains = _loop()
    shape = np.array([1e-4, 1e-4, 5e-3, 5e-3])
    tube = tube_gains(plant.Ad, plant.Gd, gains, shape)
    a = closed_loop(plant.Ad, plant.Gd, gains)
    # Ψ(k, j+1) by direct products, independent of the tube's recursion.
    k = 60
    c = np.array([math.cos(0.3), math.sin(0.3)])
    psi = [np.eye(4)]
    for j in range(k - 1, 0, -1):          # Ψ(k, j) = Ψ(k, j+1) A_j
        psi.insert(0, psi[0] @ a[j])
    # The sequence d_j = s ∘ sign(cᵀPΨ(k, j+1)), simulated step by step from rest.
    x = np.zeros(4)
    for j in range(k):
        x = a[j] @ x + shape * np.sign(c @ psi[j][:2])
    attained = abs(c @ x[:2])
    assert attained == pytest.approx(sum((np.abs(c @ p[:2]) * shape).sum() for p in psi))
    # Over all directions (fine grid) the worst sequence stays under the tube, and the
    # tube is within the direction-grid factor of it.
    angles = np.linspace(0, math.pi, 721)
    worst = max(sum((np.abs(np.array([math.cos(t), math.sin(t)]) @ p[:2]) * shape).sum()
                    for p in psi) for t in angles)
    assert worst <= tube[k - 1] <= worst / math.cos(math.pi / 32) + 1e-12
    # 500 random sequences within the box: every step, every direction, under the tube.
    rng = np.random.default_rng(1)
    d = shape * rng.uniform(-1, 1, (500, len(gains), 4))
    x = np.zeros((500, 4))
    for j in range(len(gains)):
        x = x @ a[j].T + d[:, j]
        assert np.linalg.norm(x[:, :2], axis=1).max() <= tube[j] + 1e-12


def test_random_deviation_matches_monte_carlo():
    plant, gains = _loop()
    noise = np.array([1e-4, 1e-4, 2e-3, 2e-3])
    probing, rho = 5.0, 0.95
    spread = random_deviation(plant.Ad, plant.Gd, gains, noise, probing, rho)
    a = closed_loop(plant.Ad, plant.Gd, gains)
    rng = np.random.default_rng(2)
    runs = 4000
    p = probing * rng.standard_normal((runs, 2))
    x = np.zeros((runs, 4))
    ys = []
    for j in range(len(gains)):
        x = x @ a[j].T + p @ plant.Gd.T + noise * rng.standard_normal((runs, 4))
        p = rho * p + math.sqrt(1 - rho**2) * probing * rng.standard_normal((runs, 2))
        ys.append(x[:, 1].std())
    # The y axis is one direction: its spread is the worst direction's for this isotropic loop.
    np.testing.assert_allclose(ys, spread, rtol=0.06)


def test_nominal_deviation_is_the_simulated_deviation_from_the_leg_line():
    plant, gains = _loop()
    start = np.array([0.0, 0.0, 0.2, 0.5])          # moving sideways at the leg start
    target = np.array([4.0, 0.0])
    dev = nominal_deviation(plant.Ad, plant.Gd, np.zeros((4, 2)), gains, start[None],
                            target[None])
    x = start.copy()
    worst = 0.0
    for k in range(len(gains)):
        xbar = x - np.concatenate([target, np.zeros(2)])
        x = plant.step(x, -gains[k] @ xbar)
        worst = max(worst, abs(x[1]))
    assert dev[0] == pytest.approx(worst, rel=1e-9)
    assert worst > 0.05


def test_step_levels_tube_is_attained_across_the_leg_and_sums_to_the_uniform_tube():
    plant, gains = _loop()
    shape = np.array([1e-4, 1e-4, 5e-3, 5e-3])
    c = np.array([math.cos(1.1), math.sin(1.1)])
    worst, along = leg_tube_terms(plant.Ad, plant.Gd, gains, shape, c)
    # A uniform level gives back the tube of tube_gains.
    tube = tube_gains(plant.Ad, plant.Gd, gains, shape)
    np.testing.assert_allclose(worst.sum(axis=1).max(axis=1) / math.cos(math.pi / 32), tube,
                               rtol=1e-12)
    # Levels that change along the leg: the sequence d_j = ℓ_j s ∘ sign(cᵀPΨ(k, j+1)),
    # simulated from rest, attains Σ_j ℓ_j along[k-1, j] across the line at step k.
    rng = np.random.default_rng(2)
    levels = rng.uniform(0.0, 3.0, len(gains))
    a = closed_loop(plant.Ad, plant.Gd, gains)
    k = 80
    psi = [np.eye(4)]
    for j in range(k - 1, 0, -1):
        psi.insert(0, psi[0] @ a[j])
    x = np.zeros(4)
    for j in range(k):
        x = a[j] @ x + levels[j] * shape * np.sign(c @ psi[j][:2])
    assert abs(c @ x[:2]) == pytest.approx(levels[:k] @ along[k - 1, :k])
    assert np.all(along[k - 1, k:] == 0.0)


def test_nominal_path_is_the_simulated_response():
    plant, gains = _loop()
    start = np.array([1.0, -2.0, 0.4, 0.3])
    target = np.array([4.0, 2.0])
    pos, dev = nominal_path(plant.Ad, plant.Gd, np.zeros((4, 2)), gains, start, target)
    a = closed_loop(plant.Ad, plant.Gd, gains)
    xbar = start - np.array([*target, 0.0, 0.0])
    line = (target - start[:2]) / np.linalg.norm(target - start[:2])
    for k in range(len(gains)):
        xbar = a[k] @ xbar
        np.testing.assert_allclose(pos[k], xbar[:2] + target, atol=1e-12)
        assert dev[k] == pytest.approx(abs(line[0] * xbar[1] - line[1] * xbar[0]), abs=1e-12)
    assert dev.max() == pytest.approx(float(nominal_deviation(
        plant.Ad, plant.Gd, np.zeros((4, 2)), gains, start[None], target[None])[0]))


def test_an_expanding_learned_closed_loop_is_flagged_and_the_true_rovers_is_not():
    """The tube through a closed loop that expands bounds nothing (an early model with a mode
    of radius 1.05 gave margins of 1e9 m); the true rover's, even at the zero gain where
    the position has an eigenvalue of exactly 1, is not flagged, nor a little noise on it."""
    dt, N = 0.05, 200
    A, B = ref.rover(mass=40.0, stiffness=0.0, damping=45.0)
    phi, gamma = ref.zoh(A, B, dt)
    zero = np.zeros((N, 2, 4))
    pd = np.tile(np.array([[40.0, 0, 30.0, 0], [0, 40.0, 0, 30.0]]), (N, 1, 1))
    assert not expanding(phi, gamma, zero) and not expanding(phi, gamma, pd)
    noisy = phi + 1e-3 * np.random.default_rng(0).standard_normal(phi.shape)
    assert not expanding(noisy, gamma, zero)
    bad = phi.copy()
    bad[0, 0] = 1.05                                      # a position that grows 5 % a step
    assert expanding(bad, gamma, zero)
    assert tube_gains(bad, gamma, zero, np.ones(4)).max() > 100 * tube_gains(
        phi, gamma, zero, np.ones(4)).max()               # what its tube would have said
