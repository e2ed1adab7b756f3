"""A margin policy's mission on the true rover: waypoints, a PD law with probing, a field bump.

Shared by the tests of the margin policies (``tests/test_margins_policy.py``,
``tests/test_margins_calibrated.py``): the plant, field and controller are known, so what a
policy publishes can be checked against them.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from rrtq_controller.legs import LegSequencer
from rrtq_planner.margins.policy import LegInfo, MarginSample
from rrtq_sim.field import Bump, DisturbanceField, compose_input_matrix
from rrtq_sim.plant import Plant, rover_matrices

__all__ = ['PD', 'rover_mission']


PD = np.array([[40.0, 0.0, 30.0, 0.0], [0.0, 40.0, 0.0, 30.0]])


def rover_mission(policy, steps=3000, seed=0):
    """Fly ``policy`` through one mission; returns (status, leg index) per step, plant, field.

    The rover without a spring between random waypoints of a 12 m square under a PD law
    with probing that decays leg by leg (strong on the first: the transient), through a field
    bump. (Waypoints in varied directions: along a straight route the legs' frame moves with
    the robot and a model-free fit cannot tell a field from a spring; see docs/margins.md.)
    """
    a_mat, b_mat = rover_matrices(40.0, 0.0, 45.0)
    dt = 0.05
    plant = Plant(a_mat, b_mat, compose_input_matrix(None, 4), dt, 1000.0)
    field = DisturbanceField([Bump((6.0, 6.0), 4.0, (0.15, -0.2))])
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((steps, 2))
    probe = lfilter([np.sqrt(1 - 0.95**2)], [1.0, -0.95], white, axis=0)
    route = rng.uniform(0.0, 12.0, (60, 2))
    legs = LegSequencer(rho=0.15, horizon=10.0)
    x = np.zeros(4)
    legs.set_plan(route, x, 0.0)
    rows = []
    prev = None
    for k in range(steps):
        t = k * dt
        sample = MarginSample(t, x) if prev is None else MarginSample(
            t, x, prev['leg'], prev['u'], prev['probe'], lambda tau: PD, 10.0)
        status = policy.step(sample)
        rows.append((status, None if prev is None else prev['leg'].index))
        legs.update(x, t)
        leg = legs.leg
        std = 60.0 * 0.6 ** leg.index
        p = std * probe[k]
        u = -PD @ (x - leg.target) + p
        prev = {'leg': LegInfo(leg.index, leg.x0[:2].copy(), leg.target[:2].copy(), leg.d0),
                'u': u, 'probe': p}
        x = plant.step(x, u, field.acceleration(x), np.zeros(2))
    return rows, plant, field
