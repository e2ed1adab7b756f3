"""Otte's bottleneck experiment (BNeck.txt): replanning when the plug vanishes."""

import numpy as np

from rrtq_planner.rrtx import RRTX, PlanStatus, RRTXConfig
from rrtq_testing.paths import OTTE, read_otte

DATA = OTTE
RADIUS = 0.5
ROBOT = (0.0, 40.0)
GOAL = (0.0, -40.0)


def grown_box(poly, r):
    """Conservative growth of an axis-aligned box: its box expanded by r.

    The Minkowski sum with a disc of radius r lies inside it (square corners).
    """
    lo = poly.min(axis=0) - r
    hi = poly.max(axis=0) + r
    return np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])


def clearance(path, box_poly, spacing=0.01):
    """Smallest distance from the densely sampled path to an axis-aligned box."""
    lo = box_poly.min(axis=0)
    hi = box_poly.max(axis=0)
    best = np.inf
    for p, q in zip(path[:-1], path[1:]):
        m = max(2, int(np.ceil(np.linalg.norm(q - p) / spacing)) + 1)
        pts = p + np.linspace(0.0, 1.0, m)[:, None] * (q - p)
        d = np.linalg.norm(np.maximum(np.maximum(lo - pts, pts - hi), 0.0), axis=1)
        best = min(best, float(d.min()))
    return best


def test_bneck_goes_around_the_wall_then_through_the_gap():
    left, right, plug = read_otte(DATA / "BNeck.txt")
    cfg = RRTXConfig(
        goal=GOAL, bounds=(-50.0, 50.0, -50.0, 50.0), steer_distance=5.0, robot_radius=RADIUS
    )
    planner = RRTX(cfg, np.random.default_rng(4))
    for oid, poly in (("left", left), ("right", right), ("plug", plug)):
        planner.add_obstacle(oid, grown_box(poly, RADIUS))
    planner.set_robot(ROBOT)
    planner.run(2000)
    assert planner.status is PlanStatus.FOUND
    # Shortest way around a grown wall end at (+-40.5, +-0.6).
    around = 2.0 * np.hypot(40.5, 39.4) + 1.2
    assert around - 1e-9 <= planner.cost() <= 1.1 * around
    path = planner.path()
    for poly in (left, right, plug):
        assert clearance(path, poly) >= RADIUS - 1e-9

    planner.remove_obstacle("plug")
    for _ in range(60):
        if planner.cost() < 85.0:
            break
        planner.run(100)
    assert 80.0 - 1e-9 <= planner.cost() < 85.0
    path = planner.path()
    assert np.all(np.abs(path[:, 0]) < 10.0)  # through the gap, not around
    for poly in (left, right):
        assert clearance(path, poly) >= RADIUS - 1e-9
