"""The open-loop force player: piecewise constant from each time, zero before the first."""

import numpy as np
import pytest

from rrtq_controller.open_loop import ForceProfile


def test_piecewise_constant_profile():
    profile = ForceProfile.from_rows([[1.0, 5.0, 0.0], [2.5, 0.0, -3.0]])
    assert profile.force_at(0.5).tolist() == [0.0, 0.0]
    assert profile.force_at(1.0).tolist() == [5.0, 0.0]
    assert profile.force_at(2.4999).tolist() == [5.0, 0.0]
    assert profile.force_at(2.5).tolist() == [0.0, -3.0]
    assert profile.force_at(9.0).tolist() == [0.0, -3.0]
    # A step time reached through float round-off of k * dt still switches on time.
    assert profile.force_at(50 * 0.05).tolist() == [0.0, -3.0]


def test_times_must_increase():
    with pytest.raises(ValueError):
        ForceProfile.from_rows(np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 1.0]]))
