"""The referee: true clearance and collision, the bounds, both latched.

Ground truth: shapely's distances for the obstacles, hand-worked distances for the bounds.
"""

import math

import numpy as np
import pytest
import shapely

from rrtq_common.world import ObstacleSpec
from rrtq_sim.referee import Referee, bounds_clearance

BOUNDS = ((-5.0, 5.0), (-2.0, 3.0))
SQUARE = ObstacleSpec('box', np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]))
TRIANGLE = ObstacleSpec('tri', np.array([[3.0, -1.0], [4.0, -1.0], [3.5, 0.0]]))


@pytest.mark.parametrize('position, expected', [
    ((0.0, 0.0), 2.0),            # nearest edge: y = -2
    ((4.5, 2.9), 0.1),
    ((5.0, 1.0), 0.0),            # on the edge: inside
    ((5.3, 1.0), -0.3),
    ((-5.3, -2.4), -0.5),         # beyond a corner: the distance to it
    ((0.0, 7.0), -4.0),
])
def test_bounds_clearance_is_the_signed_distance_to_the_rectangle(position, expected):
    assert bounds_clearance(position, BOUNDS) == pytest.approx(expected, abs=1e-12)


def test_clearance_is_the_discs_distance_to_the_nearest_existing_obstacle():
    referee = Referee(0.25, BOUNDS)
    rng = np.random.default_rng(1)
    shapes = [shapely.Polygon(spec.polygon) for spec in (SQUARE, TRIANGLE)]
    for p in rng.uniform((-4.0, -1.5), (4.0, 2.5), (40, 2)):
        judged = referee.judge(p, (SQUARE, TRIANGLE))
        distances = [shape.distance(shapely.Point(p)) for shape in shapes]
        nearest = int(np.argmin(distances))
        if distances[nearest] > 0.0:
            assert judged.clearance == pytest.approx(distances[nearest] - 0.25, abs=1e-9)
            assert judged.nearest == ('box', 'tri')[nearest]


def test_nothing_existing_is_an_infinite_clearance_and_no_collision():
    judged = Referee(0.5, BOUNDS).judge((0.5, 0.5), ())
    assert math.isinf(judged.clearance) and judged.nearest == '' and not judged.collision


def test_collision_and_out_of_bounds_latch():
    referee = Referee(0.25, BOUNDS)
    path = [(-1.0, 0.5), (-0.1, 0.5), (-1.0, 0.5), (5.2, 0.5), (4.0, 0.5)]
    judged = [referee.judge(p, (SQUARE,)) for p in path]
    assert [j.collision for j in judged] == [False, True, True, True, True]
    assert judged[1].clearance == pytest.approx(-0.15)
    assert [j.out_of_bounds for j in judged] == [False, False, False, True, True]
    assert judged[3].bounds_clearance == pytest.approx(-0.2)
    assert judged[4].bounds_clearance == pytest.approx(1.0)     # back in, still latched
