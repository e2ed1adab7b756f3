"""The actuator's delay: the delay line, and the simulation it delays.

Ground truth for the delayed run is the undelayed run of the same plant, shifted by the
delay: a plant at rest at its equilibrium under zero force stays there, so delaying the
whole force sequence by d steps delays the whole trajectory by d steps, exactly.
"""

import numpy as np
import pytest

from rrtq_sim.plant import Plant, SpringAnchor, rover_matrices
from rrtq_sim.simulation import DelayLine, Simulation, delay_steps

DT = 0.05


def test_the_delay_line_gives_zeros_then_what_went_in_steps_later():
    line = DelayLine(3, 2)
    pushed = [np.array([float(k), -float(k)]) for k in range(1, 8)]
    out = [line.shift(u) for u in pushed]
    assert all(np.array_equal(o, np.zeros(2)) for o in out[:3])
    assert all(np.array_equal(o, u) for o, u in zip(out[3:], pushed))


def test_the_delay_line_keeps_what_it_was_given_not_a_later_change():
    line = DelayLine(1, 2)
    u = np.array([1.0, 2.0])
    line.shift(u)
    u[:] = 9.0                            # the caller reuses its array
    assert np.array_equal(line.shift(np.zeros(2)), [1.0, 2.0])


def test_no_delay_hands_the_force_through():
    line = DelayLine(0, 2)
    u = np.array([4.0, 5.0])
    assert line.shift(u) is u


@pytest.mark.parametrize('delay, steps', [(0.0, 0), (0.05, 1), (0.15, 3), (1.0, 20)])
def test_delay_steps_of_whole_multiples(delay, steps):
    assert delay_steps(delay, DT) == steps


@pytest.mark.parametrize('delay', [0.07, 0.025, -0.05, float('inf'), float('nan')])
def test_delay_steps_refuses_what_is_no_whole_multiple(delay):
    with pytest.raises(ValueError):
        delay_steps(delay, DT)


def _run(delay, forces, anchor=SpringAnchor.WORLD_ORIGIN):
    a, b = rover_matrices(40.0, 20.0, 45.0)
    sim = Simulation(Plant(a, b, None, DT, 1000.0), (0.0, 0.0), anchor, 0.0, delay)
    states = [sim.x.copy()]
    for u in forces:
        sim.hold_force(u)
        sim.advance()
        states.append(sim.x.copy())
    return np.array(states)


@pytest.mark.parametrize('delay', [1, 4])
def test_a_delayed_run_is_the_undelayed_run_later(delay):
    rng = np.random.default_rng(2)
    forces = rng.uniform(-100.0, 100.0, (60, 2))
    now, later = _run(0, forces), _run(delay, forces)
    assert np.all(later[:delay + 1] == 0.0)              # at rest until the first force acts
    assert np.array_equal(later[delay:], now[:len(now) - delay])
    assert not np.array_equal(later, now)


def test_the_spring_anchor_is_not_delayed():
    # The anchor moves at once: under zero force, a robot anchored at (1, 0) is pulled
    # toward it from the first step, with or without a force delay.
    a, b = rover_matrices(40.0, 20.0, 45.0)
    runs = []
    for delay in (0, 5):
        sim = Simulation(Plant(a, b, None, DT, 1000.0), (0.0, 0.0), SpringAnchor.LEG_TARGET,
                         0.0, delay)
        sim.follow_target([1.0, 0.0])
        sim.advance()
        runs.append(sim.x.copy())
    assert runs[0][0] > 0.0 and np.array_equal(runs[0], runs[1])
