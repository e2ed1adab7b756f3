"""The vf_lpc driver as the node runs it: model file, reference and obstacles in, force out.

A model identified for the 40 kg rover drives a 60 kg one (the true zero-order hold of
rrtq_testing) along a straight reference at 1.5 m/s: every command within the actuator
limit, the GP fed from the second step on, its predictions scored against the true next
states (better than the nominal model's), and the state's fields as documented.
"""

import dataclasses

import numpy as np
import pytest

from rrtq_common.lockstep import OnChange
from rrtq_controller.config import ControllerConfig, Variant
from rrtq_controller.drivers import make_driver
from rrtq_controller.vf_lpc import LPCConfig, fit_edmd
from rrtq_testing.controller_reference import rover, zoh

DT = 0.05
LIMIT = 150.0


@pytest.fixture(scope='module')
def model_file(tmp_path_factory):
    a, b = zoh(*rover(40.0, 0.0, 45.0), DT)
    rng = np.random.default_rng(4)
    x, u = rng.normal(size=(300, 4)), rng.normal(scale=100.0, size=(300, 2))
    path = tmp_path_factory.mktemp('m') / 'model.npz'
    fit_edmd(x, u, x @ a.T + u @ b.T, DT, force_limit=1000.0).save(path)
    return path


def reference(t, count=101, speed=1.5):
    times = t + DT * np.arange(count)
    pos = np.column_stack((speed * times, np.zeros(count)))
    return np.hstack((pos, np.tile([speed, 0.0], (count, 1))))


def test_driver_tracks_within_the_limit_and_learns_the_heavier_plant(model_file):
    config = ControllerConfig(variant=Variant.VF_LPC, model=str(model_file), force_limit=LIMIT)
    driver = make_driver(config, 4, 2, 1, np.random.default_rng(0),
                         lpc=dataclasses.replace(LPCConfig(), force_limit=1000.0))
    assert driver.lpc.force_limit == LIMIT               # the actuator's, not the solver's own
    a, b = zoh(*rover(60.0, 0.0, 45.0), DT)
    wall = [np.array([[-5.0, 3.0], [40.0, 3.0], [40.0, 4.0], [-5.0, 4.0]])]
    x = np.array([0.0, -0.5, 0.0, 0.0])
    outs = []
    for k in range(160):
        t = k * DT
        out = driver.control(t, x, None, None,
                             OnChange(k * 50_000_000, lambda t=t: (reference(t), 2 if k >= 80 else 1)),
                             OnChange(0, lambda: wall))
        assert out is not None
        outs.append(out)
        x = a @ x + b @ out.u
    forces = np.array([o.u for o in outs])
    assert np.abs(forces).max() <= LIMIT and np.abs(forces).max() == pytest.approx(LIMIT)
    assert outs[0].prediction_error.size == 0 and outs[1].prediction_error.size == 4
    assert [o.leg_index for o in (outs[0], outs[79], outs[80])] == [1, 1, 2]
    assert outs[80].leg_start_time == pytest.approx(80 * DT)
    learned = np.array([o.prediction_error[2:] for o in outs[20:]])
    nominal = np.array([o.nominal_error[2:] for o in outs[20:]])
    assert np.sqrt(np.mean(learned ** 2)) < 0.5 * np.sqrt(np.mean(nominal ** 2))
    assert outs[-1].gp_dictionary > 0 and outs[-1].prediction_std.shape == (4,)
    last = outs[-1]
    ref = reference(159 * DT)
    np.testing.assert_allclose(last.leg_start, ref[0, :2])
    np.testing.assert_allclose(last.leg_target, ref[20, :2])
    assert last.d0 == pytest.approx(1.5 * 20 * DT)
    assert last.tracking_error == pytest.approx(np.hypot(*(x_prev(outs, a, b) - ref[0, :2])))
    assert last.tracking_error < 0.1 and last.actor_weights.shape == (40,)


def x_prev(outs, a, b):
    """The position the last command was computed at (replayed from the start)."""
    x = np.array([0.0, -0.5, 0.0, 0.0])
    for o in outs[:-1]:
        x = a @ x + b @ o.u
    return x[:2]


def test_driver_without_a_reference_commands_zero(model_file):
    config = ControllerConfig(variant=Variant.VF_LPC, model=str(model_file), force_limit=LIMIT)
    driver = make_driver(config, 4, 2, 1, np.random.default_rng(0))
    out = driver.control(0.0, np.array([1.0, 2.0, 0.0, 0.0]), None, None)
    assert out is not None and np.array_equal(out.u, [0.0, 0.0]) and out.event == 'no_plan'
