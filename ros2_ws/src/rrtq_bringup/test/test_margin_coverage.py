"""The recording-only coverage check: which margin a leg is judged against, which leg a step
belongs to, and the binomial verdict."""

from types import SimpleNamespace

import numpy as np
import pytest

from rrtq_bringup.margin_coverage import Coverage, LegCoverage, leg_coverage


def _state(t, index, start=(0.0, 0.0), target=(10.0, 0.0), d0=10.0):
    stamp = SimpleNamespace(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))
    return SimpleNamespace(header=SimpleNamespace(stamp=stamp), leg_index=index,
                           leg_start=SimpleNamespace(x=start[0], y=start[1]),
                           leg_target=SimpleNamespace(x=target[0], y=target[1]), d0=d0)


def test_a_margin_raised_during_the_leg_does_not_cover_it():
    # Leg 0 (steps 0.1-0.3) strays 0.6 m while 0.3 m was published at its start and the
    # margin followed the deviation up (raised at once): a miss. Leg 1 starts at 0.4 (its
    # state stamped 0.35, read at the next step) and stays within its 0.7 m.
    states = [_state(0.05, 0), _state(0.35, 1, start=(5.0, 0.6), target=(5.0, 10.0))]
    odom = [(0.1, np.array([1.0, 0.1])), (0.2, np.array([2.0, 0.6])),
            (0.3, np.array([3.0, 0.2])), (0.4, np.array([5.0, 0.6])),
            (0.5, np.array([5.5, 1.0]))]
    radius = 0.5
    statuses = [(0.1, 0.3 + radius), (0.2, 0.6 + radius), (0.3, 0.6 + radius),
                (0.4, 0.7 + radius), (0.5, 0.7 + radius)]
    legs = leg_coverage(odom, states, statuses, radius)
    assert [leg.index for leg in legs] == [0, 1]
    assert (legs[0].deviation, legs[0].margin) == pytest.approx((0.6, 0.3)) and not legs[0].covered
    assert (legs[1].deviation, legs[1].margin) == pytest.approx((0.5, 0.7)) and legs[1].covered


def test_verdict_is_the_lower_end_of_the_miss_rate_interval_against_delta():
    def legs(misses, n):
        return [LegCoverage(i, 0.0, 1.0, 1.0 if i < misses else 0.0, 0.5) for i in range(n)]
    assert Coverage('conformal', 0.05, legs(2, 8)).passed           # 2/8: [0.032, 0.651]
    assert not Coverage('conformal', 0.05, legs(3, 8)).passed       # 3/8: [0.085, 0.755]
    assert not Coverage('conformal', 0.05, legs(17, 67)).passed
    assert Coverage('conformal', 0.05, legs(3, 227)).passed
