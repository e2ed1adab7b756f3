"""The one reading of a recording's legs off /safety/status (run_data.safety_legs)."""

from types import SimpleNamespace

import pytest

from rrtq_bringup.run_data import safety_legs


def _status(t, legs, leg_index, margin, leg_margin, deviation, tube=0.0, scale=1.0,
            refuted=False):
    stamp = SimpleNamespace(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))
    return SimpleNamespace(header=SimpleNamespace(stamp=stamp), legs=legs, leg_index=leg_index,
                           margin=margin, leg_margin=leg_margin, leg_deviation=deviation,
                           leg_tube=tube, scale=scale, leg_refuted=refuted)


def test_a_leg_is_its_start_margin_and_tube_and_its_last_deviation():
    """Statuses before the first leg belong to none; a leg's margin in force, tube and scale
    are those at its start, its deviation the last reported (the largest so far), its least
    margin the least published while it ran (a margin raised within the leg does not count)."""
    statuses = [
        _status(0.0, 0, 0, 0.0, 0.0, 0.0),
        _status(0.5, 1, 0, 0.30, 0.30, 0.05, tube=0.2, scale=1.5),
        _status(1.0, 1, 0, 0.25, 0.40, 0.20, tube=0.9, scale=9.0, refuted=True),
        _status(1.5, 2, 1, 0.40, 0.40, 0.10),
        _status(2.0, 2, 2, 0.45, 0.45, 0.30),
    ]
    first, second = safety_legs(statuses)
    assert (first.index, first.start, first.margin) == (1, 0.5, 0.30)
    assert (first.tube, first.scale, first.refuted) == (0.2, 1.5, False)
    assert first.deviation == 0.20 and first.least_margin == 0.25
    assert (second.index, second.start, second.deviation, second.least_margin) == (
        2, 1.5, 0.30, pytest.approx(0.40))
    by_controller = safety_legs(statuses, by='leg_index')
    assert [leg.index for leg in by_controller] == [0, 1, 2]
    assert by_controller[2].margin == 0.45


def test_a_recording_older_than_the_refuted_flag_says_so():
    old = _status(0.5, 1, 0, 0.3, 0.3, 0.1)
    del old.leg_refuted
    assert safety_legs([old])[0].refuted is None
