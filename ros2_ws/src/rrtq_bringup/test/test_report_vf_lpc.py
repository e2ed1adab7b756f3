"""The report's v²κ of a driven path, against a circle driven at constant speed (v²/r)."""

import numpy as np

from rrtq_bringup.report.vf_lpc import lateral_acceleration


def circle(speed, radius, dt=0.05, steps=200):
    t = dt * np.arange(steps)
    w = speed / radius
    x = np.column_stack((radius * np.cos(w * t), radius * np.sin(w * t),
                         -speed * np.sin(w * t), speed * np.cos(w * t)))
    return t, x


def test_lateral_acceleration_of_a_circle_is_v2_over_r():
    t, x = circle(2.0, 4.0)
    lateral, jerk = lateral_acceleration(t, x)
    assert len(lateral) == len(t)
    assert np.allclose(lateral[1:-1], 2.0 ** 2 / 4.0, rtol=1e-3)
    # |jerk| of uniform circular motion: v³/r².
    assert np.allclose(jerk[2:-2], 2.0 ** 3 / 4.0 ** 2, rtol=2e-3)


def test_a_republished_odometry_sample_counts_once():
    # The simulator republishes a step's /odom when an acknowledgement is late: the same
    # stamp twice must not become a zero time step (inf / NaN) in the differences.
    t, x = circle(2.0, 4.0)
    td, xd = np.insert(t, 50, t[50]), np.insert(x, 50, x[50], axis=0)
    lateral, jerk = lateral_acceleration(td, xd)
    assert np.all(np.isfinite(lateral)) and np.all(np.isfinite(jerk))
    ref_lateral, ref_jerk = lateral_acceleration(t, x)
    assert np.array_equal(lateral, ref_lateral) and np.array_equal(jerk, ref_jerk)
