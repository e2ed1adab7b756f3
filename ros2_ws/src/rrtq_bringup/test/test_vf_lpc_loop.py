"""VF-LPC closed loop without ROS: RRT^X path, guidance, vf_lpc, the exact plant.

The model is identified by EDMD from probing data of one plant; the loop runs on that
plant or on a heavier one with acceleration bumps on the route. Judged by the referee's
distance to the true obstacles, the actuator limit, the reference's own curvature bound
and the one-step prediction errors against the true next states.
"""

import numpy as np
import pytest

from rrtq_bringup.vf_lpc_harness import Bump, identify_by_probing, rover_plant, run_closed_loop
from rrtq_controller.vf_lpc import LPCConfig
from rrtq_common.geometry import polygon_from_circle

OBSTACLES = [polygon_from_circle((8.0, 1.0), 1.5, 16),
             np.array([[12.0, -6.0], [14.0, -6.0], [14.0, 3.0], [12.0, 3.0]]),
             polygon_from_circle((18.0, 5.0), 1.0, 16)]
BUMPS = [Bump((5.0, -1.0), 3.0, (0.0, 2.0)), Bump((20.0, 2.0), 3.0, (-1.5, 1.5))]
START, GOAL, BOUNDS = (0.0, 0.0), (25.0, 5.0), (-5.0, 30.0, -10.0, 15.0)


@pytest.fixture(scope='module')
def model():
    return identify_by_probing(rover_plant(40.0), np.random.default_rng(0))


def curvature_ok(points, dt, a_max):
    """Share of interior samples with v² kappa <= a_max (circumradius, central speed)."""
    a = np.linalg.norm(points[1:-1] - points[:-2], axis=1)
    b = np.linalg.norm(points[2:] - points[1:-1], axis=1)
    c = np.linalg.norm(points[2:] - points[:-2], axis=1)
    u, w = points[1:-1] - points[:-2], points[2:] - points[1:-1]
    cross = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
    with np.errstate(divide='ignore', invalid='ignore'):
        kappa = np.where(a * b * c > 0, 2.0 * cross / (a * b * c), 0.0)
    v = c / (2.0 * dt)
    return float(np.mean(v ** 2 * kappa <= a_max))


def test_goal_reached_without_collision_within_the_limit(model):
    result = run_closed_loop(rover_plant(40.0), model, OBSTACLES, START, GOAL, BOUNDS,
                             duration=40.0)
    assert result.reached and not result.collided and result.min_clearance > 0.0
    assert np.abs(result.commands).max() <= 1000.0
    assert result.tracking_error.max() < 0.3
    # The robot's own path respects the guidance's acceleration bound almost everywhere.
    assert curvature_ok(result.positions, 0.05, 2.0 * 1.1) >= 0.95


def test_gp_halves_the_one_step_error_under_mismatch(model):
    plant = rover_plant(70.0)
    runs = {comp: run_closed_loop(plant, model, OBSTACLES, START, GOAL, BOUNDS, bumps=BUMPS,
                                  lpc=LPCConfig(compensate=comp), duration=40.0)
            for comp in (True, False)}
    for r in runs.values():
        assert r.reached and not r.collided and np.abs(r.commands).max() <= 1000.0
    with_gp = runs[True]
    nominal = np.linalg.norm(with_gp.nominal_error[:, 2:4], axis=1).mean()
    learned = np.linalg.norm(with_gp.learned_error[:, 2:4], axis=1).mean()
    assert learned <= 0.5 * nominal
