"""VF-LPC's receding-horizon actor-critic against independent optima.

Truth: scipy's L-BFGS-B on the same costs (written here by simulation), the
infinite-horizon LQR law from scipy's discrete Riccati solution (an N-step problem whose
terminal weight is that solution has the same first input), and the referee's distance.
"""

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are
from scipy.optimize import minimize

from rrtq_controller.vf_lpc import KoopmanModel, LIFTINGS, LPCConfig, VFLPCController
from rrtq_controller.vf_lpc.lpc import box_qp
from rrtq_common.geometry import polygon_from_circle
from rrtq_common.polygon_set import PolygonSet
from rrtq_testing import controller_reference as ref

DT = 0.05


def rover_model(mass=40.0, damping=45.0):
    phi, gamma = ref.zoh(*ref.rover(mass, 0.0, damping), DT)
    return KoopmanModel(phi, gamma, np.eye(4), DT, LIFTINGS['linear'], 1000.0)


def test_box_qp_matches_lbfgsb():
    rng = np.random.default_rng(0)
    for _ in range(20):
        m = rng.normal(size=(12, 12))
        H = m @ m.T + 0.1 * np.eye(12)
        g = rng.normal(size=12) * 5.0
        lo, hi = -np.ones(12), np.ones(12)
        x = box_qp(H, g, lo, hi, np.zeros(12))
        ref = minimize(lambda v: 0.5 * v @ H @ v + g @ v, np.zeros(12),
                       jac=lambda v: H @ v + g, bounds=list(zip(lo, hi)), method='L-BFGS-B',
                       options={'ftol': 1e-15, 'gtol': 1e-12})
        assert np.all(x >= lo) and np.all(x <= hi)
        assert 0.5 * x @ H @ x + g @ x <= ref.fun + 1e-9


def controller(**kw):
    cfg = LPCConfig(compensate=False, barrier_obstacles=0, **kw)
    return VFLPCController(rover_model(), cfg)


def test_unconstrained_first_input_is_the_lqr_law():
    ctrl = controller(iterations=1)
    mdl = ctrl.model
    Q, R = ctrl.solver.Q, ctrl.solver.R
    P = solve_discrete_are(mdl.A, mdl.B, Q, R)
    K = np.linalg.solve(R + mdl.B.T @ P @ mdl.B, mdl.B.T @ P @ mdl.A)
    x0 = np.array([0.3, -0.2, 0.1, 0.05])
    u, _ = ctrl.step(x0, np.zeros((21, 4)))
    assert np.abs(u).max() < 1000.0
    assert np.allclose(u, -K @ x0, rtol=1e-6, atol=1e-6)


def test_saturated_inputs_are_the_bounded_optimum():
    ctrl = controller(iterations=1, force_limit=200.0)
    mdl, N = ctrl.model, ctrl.config.horizon_steps
    Q, R, P = ctrl.solver.Q, ctrl.solver.R, ctrl.solver.P
    x0 = np.array([8.0, -5.0, 0.0, 1.0])
    ref = np.zeros((N + 1, 4))

    def cost(flat):
        x, total = x0, 0.0
        for k, u in enumerate(flat.reshape(N, 2)):
            x = mdl.A @ x + mdl.B @ u
            total += u @ R @ u + (x @ P @ x if k == N - 1 else x @ Q @ x)
        return total

    u, sol = ctrl.step(x0, ref)
    assert np.abs(sol.inputs).max() <= 200.0 + 1e-9 and np.isclose(np.abs(u).max(), 200.0)
    best = minimize(cost, np.zeros(2 * N), bounds=[(-200.0, 200.0)] * (2 * N),
                    method='L-BFGS-B', options={'ftol': 1e-15, 'gtol': 1e-10,
                                                'maxiter': 5000})
    assert cost(sol.inputs.reshape(-1)) <= best.fun * (1.0 + 1e-6)


@pytest.mark.parametrize('weight', [50.0, 0.0])
def test_barrier_bends_the_prediction_around_an_obstacle(weight):
    disc = polygon_from_circle((1.5, 0.0), 0.5, 24)
    cfg = LPCConfig(compensate=False, barrier_weight=weight, iterations=3)
    ctrl = VFLPCController(rover_model(), cfg)
    ctrl.set_obstacles([disc])
    N = cfg.horizon_steps
    ref = np.zeros((N + 1, 4))
    ref[:, 0] = np.linspace(0.0, 3.0, N + 1)        # straight through the disc, 3 m/s
    ref[:, 2] = 3.0
    x = np.array([0.0, 0.0, 3.0, 0.0])
    for _ in range(10):                              # iterations carry over step to step
        _, sol = ctrl.step(x, ref)
    clearance = min(PolygonSet([disc]).nearest(p)[0] for p in sol.states[:, :2])
    if weight > 0.0:
        assert clearance > 0.0
    else:
        assert clearance < 0.0
