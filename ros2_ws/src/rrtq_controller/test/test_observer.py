"""The observer: a one-step model identified from odometry and forces, smoothing, the equivalent input.

Ground truth: the true plant's exact zero-order-hold discretisation
(``rrtq_testing.controller_reference``), which the observer never sees.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rrtq_controller import observer as observer_module
from rrtq_controller.observer import Observer
from rrtq_testing import controller_reference as ref

DT = 0.05
F = ref.MAXWELL_SLIP_F


def _drive(observer: Observer, *, seconds: float = 150.0, delay: int = 0,
           disturbance: str = 'none', amplitude: float = 0.5, noise: tuple[float, float] = (0.0, 0.0),
           mass: float = 40.0, damping: float = 45.0, stiffness: float = 0.0, seed: int = 0,
           probing: float = 30.0):
    """A PD-held robot with slow probing, legs of 10 s, the observer fed as the controller feeds it.

    Returns the true states, the measured ones, the applied forces and the disturbance
    (per step), and the true (Φ, Γ).
    """
    A, B = ref.rover(mass, stiffness, damping)
    plant = ref.Plant(A, B, DT, F)
    Phi, Gam = ref.zoh(A, B, DT)
    rng = np.random.default_rng(seed)
    K = np.array([[40.0, 0.0, 30.0, 0.0], [0.0, 40.0, 0.0, 30.0]])
    a = math.exp(-DT)
    probe = np.zeros(2)
    pending = [np.zeros(2)] * delay
    truth, measured, applied, pushes = [], [], [], []
    x = np.zeros(4)
    segment = 0
    sp, sv = noise
    for k in range(int(seconds / DT)):
        if k % 200 == 0:                      # a new leg: a new target 2-8 m away
            segment += 1
            x = np.concatenate([ref.random_legs(rng, 1, 2.0, 8.0)[0], x[2:]])
        y = x + rng.standard_normal(4) * np.array([sp, sp, sv, sv])
        probe = a * probe + math.sqrt(1 - a * a) * probing * rng.standard_normal(2)
        u = -K @ y + probe
        observer.record(y, u, segment, sensitivity=-K)   # as the controller records it
        pending.append(u)
        ua = pending.pop(0)
        t = k * DT
        d = {'none': 0.0, 'white': amplitude * rng.standard_normal(),
             'sinusoid': amplitude * math.sin(2 * math.pi * 0.2 * t)}[disturbance]
        truth.append(x.copy()), measured.append(y), applied.append(ua), pushes.append(d)
        x = plant.step(x, ua, np.array([d]))
    return (np.array(truth), np.array(measured), np.array(applied), np.array(pushes), Phi, Gam)


def test_identifies_the_exact_model_and_the_delay_from_exact_data():
    for delay in (0, 2):
        obs = Observer(4, 2, lags=3, memory=4000)
        *_, Phi, Gam = _drive(obs, delay=delay)
        assert obs.update()
        model = obs.model
        assert model is not None
        assert np.abs(model.phi - Phi).max() < 1e-8
        assert np.abs(model.gammas[delay] - Gam).max() < 1e-10
        assert np.abs(np.delete(model.gammas, delay, axis=0)).max() < 1e-10
        assert model.delay == delay


@pytest.mark.parametrize('disturbance', ['white', 'sinusoid'])
def test_the_model_holds_under_a_disturbance_the_robot_does_not_measure(disturbance):
    """White: least squares is consistent. A 0.2 Hz sinusoid is AR(2): filtered out.

    Without the AR part the sinusoid, correlated with the state it moved, biases Φ.
    """
    obs = Observer(4, 2, lags=3, memory=4000)
    _, _, _, _, Phi, Gam = _drive(obs, disturbance=disturbance, seconds=200.0)
    obs.update()
    model = obs.model
    assert model is not None
    # Φ's velocity rows (damping, 1 - c/m Δt) and Γ within 2 %
    assert np.abs(model.phi[2:] - Phi[2:]).max() < 0.02 * np.abs(Phi[2:]).max()
    assert np.abs(model.gamma - Gam).max() < 0.02 * np.abs(Gam).max()
    if disturbance == 'sinusoid':
        w = 2 * math.pi * 0.2 * DT
        assert model.ar == pytest.approx([2 * math.cos(w), -1.0], abs=0.02)
        plain = Observer(4, 2, lags=3, memory=4000, ar=0)
        _drive(plain, disturbance=disturbance, seconds=200.0)
        plain.update()
        assert plain.model is not None
        assert (np.abs(plain.model.phi[2:] - Phi[2:]).max()
                > 5 * np.abs(model.phi[2:] - Phi[2:]).max())


def test_the_equivalent_input_is_the_applied_force_and_the_matched_push():
    """u_eff = Γ⁺(x̄_{k+1} - Φ x̄_k): the force applied (delayed) plus m·F d, the push in newtons."""
    obs = Observer(4, 2, lags=3, memory=4000)
    truth, _, applied, pushes, _, _ = _drive(obs, disturbance='white', delay=2)
    obs.update()
    steps = np.arange(obs.steps - 1500, obs.steps - 1)
    x0, x1, u, known = obs.estimates(steps)
    assert known.mean() > 0.95                  # all but the transitions across a leg
    push = 40.0 * pushes[steps, None] * F[2:, 0][None, :]
    expected = applied[steps] + push
    # the model's own estimation error (a white push is noise to least squares) is what
    # remains: a few % of the push, which the commanded force alone misses whole
    error = np.sqrt(np.mean((u[known] - expected[known]) ** 2))
    assert error < 0.05 * np.sqrt(np.mean(push ** 2))
    assert np.sqrt(np.mean((applied[steps][known] - expected[known]) ** 2)) > 0.9 * np.sqrt(
        np.mean(push ** 2))
    assert np.array_equal(x0[known], truth[steps][known])   # exact odometry: no smoothing


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_odometry_noise_fed_back_does_not_bias_the_model(seed):
    """σ_p = 0.02 m, σ_v = 0.05 m/s fed back through the PD gain, a 2-step delay, a white push.

    Least squares on the measured states is biased (errors in variables: the state's noise
    is in the regressors, and through the feedback in the force too); corrected for the
    odometry's variance and the feedback's sensitivity, and not refitted on the smoothed
    states, the model's velocity rows are right. Probing of 10 N (the controller's default
    is smaller: at 4 N the old observer's Γ came out 70-200 % high, this one's 0-24 %).
    """
    obs = Observer(4, 2, lags=3, memory=4000)
    obs.variance = np.array([0.02, 0.02, 0.05, 0.05]) ** 2
    _, _, _, _, Phi, Gam = _drive(obs, disturbance='white', delay=2, noise=(0.02, 0.05),
                                  seed=seed, probing=10.0)
    assert obs.update() and obs.model is not None
    model = obs.model
    np.testing.assert_allclose(np.diag(model.phi)[2:], np.diag(Phi)[2:], atol=0.01)
    np.testing.assert_allclose(np.diag(model.gamma[2:]), np.diag(Gam[2:]), rtol=0.10)
    # plain least squares on the same data is not (what the first identification was;
    # refitted on the smoothed states, as the observer did before, Γ came out 17-37 % high)
    y, u, segment, _ = obs._ordered()
    plain = obs.identify(y, u, segment, ar=0)
    assert plain is not None
    off = np.abs(np.diag(plain.gamma[2:]) / np.diag(Gam[2:]) - 1.0)
    assert np.max(off) > 0.10 or np.max(np.abs(np.diag(plain.phi)[2:] - np.diag(Phi)[2:])) > 0.01


def test_the_noise_correction_is_dropped_where_the_velocity_noise_exceeds_the_motion():
    """Exact positions, velocities that spread less than the noise they are said to carry
    (0.045 m/s against σ_v = 0.05 m/s: a robot that barely moves, sampled): what is left
    of ZᵀZ's states' block after the correction is not positive definite, so
    the plain fit stands. The check is on the whole states' block: counting the columns
    the correction touches took the positions' block (no noise, always definite) and
    applied the correction."""
    rng = np.random.default_rng(0)
    k = 2000
    positions = rng.normal(0.0, 3.0, (k, 2))
    velocities = rng.normal(0.0, 0.045, (k, 2))
    forces = rng.normal(0.0, 10.0, (k, 2))
    regress = np.hstack([positions, velocities, forces, np.ones((k, 1))])
    target = regress[:, :4] * 0.9 + rng.normal(0.0, 0.01, (k, 4))
    variance = np.array([0.0, 0.0, 0.05 ** 2, 0.05 ** 2])
    bias = observer_module._noise_bias(variance, np.zeros((k, 2, 4)), regress.shape[1])
    plain = observer_module._least_squares(regress, target)
    np.testing.assert_array_equal(
        observer_module._least_squares(regress, target, bias, 4), plain)
    # with more motion than noise the correction is applied
    moving = regress.copy()
    moving[:, 2:4] = rng.normal(0.0, 0.5, (k, 2))
    bias = observer_module._noise_bias(variance, np.zeros((k, 2, 4)), moving.shape[1])
    assert not np.array_equal(observer_module._least_squares(moving, target, bias, 4),
                              observer_module._least_squares(moving, target))


def test_a_column_that_never_moved_leaves_the_noise_correction_out_instead_of_failing():
    """A robot carried along x at a constant speed, exact positions, noisy velocities: its y
    position is exactly 0 on every step, its column's scale ~1e-300, and the correction's
    0 / 0 there made the states' block NaN (numpy's eigvalsh raised: "Eigenvalues did not
    converge", the controller's step with it). The fit is finite, the plain one."""
    rng = np.random.default_rng(0)
    k = 400
    x = 0.19 * 0.05 * np.arange(k)
    positions = np.column_stack([x, np.zeros(k)])
    velocities = np.column_stack([0.19 + rng.normal(0.0, 0.05, k), rng.normal(0.0, 0.05, k)])
    forces = rng.normal(0.0, 10.0, (k, 2))
    regress = np.hstack([positions, velocities, forces, np.ones((k, 1))])
    target = regress[:, :4] * 0.9 + rng.normal(0.0, 0.01, (k, 4))
    variance = np.array([0.0, 0.0, 0.05 ** 2, 0.05 ** 2])
    bias = observer_module._noise_bias(variance, np.zeros((k, 2, 4)), regress.shape[1])
    fitted = observer_module._least_squares(regress, target, bias, 4)
    assert np.all(np.isfinite(fitted))
    np.testing.assert_array_equal(fitted, observer_module._least_squares(regress, target))


def test_smoothing_brings_noisy_odometry_closer_to_the_truth():
    """σ_p = 0.02 m, σ_v = 0.05 m/s with a delay: the smoothed states and the equivalent input.

    The robot learns from these; raw, the equivalent input of one step would carry the
    velocity noise divided by Δt (m σ_v √2 / Δt ≈ 57 N).
    """
    obs = Observer(4, 2, lags=3, memory=4000)
    obs.variance = np.array([0.02, 0.02, 0.05, 0.05]) ** 2
    truth, measured, applied, pushes, _, _ = _drive(obs, disturbance='white', delay=2,
                                                    noise=(0.02, 0.05))
    assert obs.update()
    steps = np.arange(obs.steps - 3000, obs.steps - 1)
    x0, _, u, known = obs.estimates(steps)
    raw = np.sqrt(np.mean((measured[steps][known] - truth[steps][known]) ** 2, axis=0))
    smoothed = np.sqrt(np.mean((x0[known] - truth[steps][known]) ** 2, axis=0))
    assert np.all(smoothed[:2] < 0.5 * raw[:2])     # positions
    assert np.all(smoothed[2:] < 0.7 * raw[2:])     # velocities
    push = 40.0 * pushes[steps, None] * F[2:, 0][None, :]
    error = np.sqrt(np.mean((u[known] - (applied[steps] + push)[known]) ** 2))
    assert error < 0.5 * 40.0 * 0.05 * math.sqrt(2.0) / DT


def test_the_log_keeps_its_memory_and_refuses_to_learn_from_too_little():
    obs = Observer(4, 2, lags=3, memory=200)
    assert not obs.update()
    for k in range(10):
        obs.record(np.full(4, float(k)), np.zeros(2), 1)
    assert not obs.update()                     # ten steps: fewer than ten per unknown
    for k in range(500):
        obs.record(np.zeros(4), np.zeros(2), 2)
    assert obs.steps == 510
    y, *_ = obs._ordered()
    assert len(y) == 200


def test_the_steady_push_is_the_constant_push_in_newtons():
    """A constant 0.3 m/s² push through F (a slope): the observer's last second of the
    equivalent input's unexplained part is m·F·d, with a standard error it stands out of."""
    obs = Observer(4, 2, lags=3, memory=4000)
    A, B = ref.rover(40.0, 0.0, 45.0)
    plant = ref.Plant(A, B, DT, F)
    rng = np.random.default_rng(0)
    x = np.zeros(4)
    for k in range(3000):
        if k % 200 == 0:
            x = np.concatenate([ref.random_legs(rng, 1, 2.0, 8.0)[0], x[2:]])
        u = -np.array([[40.0, 0, 30.0, 0], [0, 40.0, 0, 30.0]]) @ x + 20.0 * rng.standard_normal(2)
        obs.record(x, u, k // 200)
        x = plant.step(x, u, np.array([0.3]))
    obs.update()
    mean, error = obs.steady_push(20)
    assert mean == pytest.approx(40.0 * 0.3 * F[2:, 0], abs=0.05)
    assert np.all(np.abs(mean) > 10 * error)


def test_a_robot_that_does_not_move_gives_no_model_and_no_error():
    # Coulomb friction above every command (the MuJoCo plant at mu = 0.3): the odometry is
    # constant while the forces vary. The residual is rounding noise, whose AR fit had a
    # unit root that filtered everything to zero, and the model came out NaN ("SVD did not
    # converge" ended a run). Such data say nothing of the plant: no model.
    rng = np.random.default_rng(0)
    observer = Observer(4, 2)
    x = np.array([3.0, -2.0, 0.0, 0.0])
    for _ in range(600):
        observer.record(x, rng.normal(0.0, 20.0, 2), 0)
    with np.errstate(all='ignore'):
        assert observer.update() is False
    assert observer.model is None
    model = Observer(4, 2).identify(np.tile(x, (600, 1)), rng.normal(0.0, 20.0, (600, 2)),
                                    np.zeros(600, dtype=np.int64))
    assert model is None or (np.all(np.isfinite(model.phi)) and np.all(np.isfinite(model.gamma))
                             and np.abs(model.gamma).max() < 1e-9)   # forces moved nothing


def test_a_singular_ar_fit_falls_back_to_least_squares(monkeypatch):
    # Seen with the push feed-forward on the MuJoCo plant at mu = 0.3: a warm start from a
    # unit-root AR fit gave residuals of 6e9, collinear lags, a singular Gram, and
    # np.linalg.solve's LinAlgError ended the run as node_failed. The AR fit falls back to
    # least squares (here solve is made to fail as it did there).
    import rrtq_controller.observer as observer_module

    rng = np.random.default_rng(0)
    e = np.zeros((500, 4))
    for k in range(2, 500):                  # an AR(2) process of known coefficients
        e[k] = 1.2 * e[k - 1] - 0.5 * e[k - 2] + rng.standard_normal(4)
    usable = np.ones(500, dtype=bool)
    usable[:2] = False
    expected = observer_module._ar_coefficients(e, usable, 2)

    def singular(*_args, **_kwargs):
        raise np.linalg.LinAlgError('Singular matrix')

    monkeypatch.setattr(observer_module.np.linalg, 'solve', singular)
    fallback = observer_module._ar_coefficients(e, usable, 2)
    assert np.allclose(fallback, expected, atol=1e-9)
    assert fallback == pytest.approx([1.2, -0.5], abs=0.1)


def _riccati_residual(phi: np.ndarray, Q: np.ndarray, R: np.ndarray, P: np.ndarray) -> float:
    """Relative residual of the filter's Riccati equation P = Φ(P - P(P + R)⁻¹P)Φᵀ + Q."""
    after = phi @ (P - P @ np.linalg.solve(P + R, P)) @ phi.T + Q
    return float(np.abs(after - P).max() / max(np.abs(P).max(), 1e-300))


def test_the_smoothers_covariance_survives_a_nearly_defective_model():
    """A model fitted to a robot that hardly moved (one position row zero, the velocity rows
    nearly dependent): scipy's Schur method raised "reordering failed" on it on one machine,
    inside the controller's step. The covariance is still the Riccati equation's fixed point
    (checked by its residual, not by the code under test), finite and positive semidefinite;
    on a well-conditioned model it is scipy's solution."""
    from scipy.linalg import solve_discrete_are
    phi = np.array([[0.999998268673021, 0.0, 3.9088478778394653e-07, 1.8253403689009712e-06],
                    [0.0, 0.0, 0.0, 0.0],
                    [2.3343723920356884e-04, 0.0, -2.1445893190252859e-02, 5.2085258517212622e-02],
                    [3.5674135683035855e-04, 0.0, -2.2220938279334970e-03, 4.3423983020616360e-03]])
    Q = np.array([[1.5236221793117192e-07, 0.0, 1.6751752800173855e-04, -7.7984672879079093e-05],
                  [0.0, 1e-12, 0.0, 0.0],
                  [1.6751752800173852e-04, 0.0, 4.1549099511337984e-01, -1.8774764637254945e-01],
                  [-7.7984672879079079e-05, 0.0, -1.8774764637254945e-01, 8.4899158618194068e-02]])
    R = np.diag([1e-12, 1e-12, 2.5e-3, 2.5e-3])
    P = observer_module._predicted_covariance(phi, Q, R)
    assert np.all(np.isfinite(P)) and np.allclose(P, P.T, atol=1e-12)
    assert np.linalg.eigvalsh(0.5 * (P + P.T)).min() >= -1e-12
    assert _riccati_residual(phi, Q, R, P) < 1e-6
    A, B = ref.rover(mass=40.0, stiffness=0.0, damping=45.0)
    phi_good = np.eye(4) + 0.05 * A
    Q_good, R_good = 1e-3 * np.eye(4), np.diag([4e-4, 4e-4, 2.5e-3, 2.5e-3])
    assert np.allclose(observer_module._predicted_covariance(phi_good, Q_good, R_good),
                       solve_discrete_are(phi_good.T, np.eye(4), Q_good, R_good), rtol=1e-8)
