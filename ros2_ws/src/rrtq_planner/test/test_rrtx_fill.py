"""max_nodes: past it the graph stops densifying but fills gaps, such as a vanished obstacle's.

Before, the graph froze at max_nodes: no node was ever placed where an obstacle had
been (samples inside obstacles are rejected), so when that obstacle vanished the
planner kept its detour for the rest of the run.
"""

import numpy as np
import pytest

from rrtq_planner.rrtx import RRTX, PlanStatus, RRTXConfig
from rrtq_planner.rrtx_config import FILL_FRACTION

BOUNDS = (-20.0, 20.0, -20.0, 20.0)
START, GOAL = (-15.0, 0.0), (15.0, 0.0)
BLOCK = np.array([[-4.0, -12.0], [4.0, -12.0], [4.0, 12.0], [-4.0, 12.0]])
CAP = 1200


def planner(max_nodes=CAP, seed=3):
    cfg = RRTXConfig(goal=GOAL, bounds=BOUNDS, steer_distance=3.0, max_nodes=max_nodes)
    rrtx = RRTX(cfg, np.random.default_rng(seed))
    rrtx.add_obstacle('block', BLOCK)
    rrtx.set_robot(START)
    return rrtx


def test_a_vanished_obstacle_gets_nodes_and_the_path_through_its_place():
    rrtx = planner()
    rrtx.run(4000)
    assert rrtx.node_count >= CAP and rrtx.status is PlanStatus.FOUND
    straight = float(np.hypot(GOAL[0] - START[0], GOAL[1] - START[1]))
    detour = rrtx.cost()
    assert detour > 1.2 * straight                    # around the block's ends
    rrtx.remove_obstacle('block')
    rrtx.run(3000)
    pos = rrtx.positions
    inside = np.all((pos >= BLOCK.min(axis=0)) & (pos <= BLOCK.max(axis=0)), axis=1)
    assert inside.sum() >= 10
    assert rrtx.cost() < 1.08 * straight


def test_past_max_nodes_every_new_node_lands_in_a_gap():
    rrtx = planner()
    added = []
    for _ in range(6000):
        n = rrtx.node_count
        radius = rrtx.config.ball_radius(n)
        v = rrtx.step()
        if v is not None and n >= CAP:
            added.append(v)
            gaps = np.hypot(*(rrtx.positions[:v] - rrtx.positions[v]).T)
            assert gaps.min() >= FILL_FRACTION * radius - 1e-12
    # The graph still grows where it had not reached, but it saturates.
    assert 0 < len(added) < CAP
    late = [v for v in added if v > CAP + 0.9 * len(added)]
    assert len(late) < 0.2 * len(added)


def test_without_a_limit_the_graph_keeps_densifying():
    rrtx = planner(max_nodes=None)
    rrtx.run(3000)
    capped = planner()
    capped.run(3000)
    assert rrtx.node_count > capped.node_count
    with pytest.raises(ValueError):
        RRTXConfig(goal=GOAL, bounds=BOUNDS, max_nodes=1)
