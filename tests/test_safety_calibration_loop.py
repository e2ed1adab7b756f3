"""A run writes its leg scores beside its recording; a later run starts from them.

The scores are checked against the recording itself: each leg's largest D_rob (RRT-QX
eq. 6), recomputed here from /odom and the leg of the controller's state of the step
before, not read from the safety node's status.
"""

import json
import pathlib
import subprocess

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

ROOT = pathlib.Path(__file__).resolve().parents[1]

SCENARIO = """
name: calibration-loop
seed: 3
bounds: {{x: [-10, 10], y: [-10, 10]}}
start: [-6.0, -6.0]
goal: [6.0, 5.0]
duration: {duration}
robot_radius: 0.3
plant: {{model: rover, stiffness: 0.0}}
controller:
  variant: nominal
  M: 10.0
  R: 0.02
  initial_gain: [[40, 0, 30, 0], [0, 40, 0, 30]]
  probing_std: 5.0
planner: {{steer_distance: 3.0, iterations_per_step: 20, max_nodes: 800}}
safety: {{margin: {margin}, window: 200{extra}}}
"""


def run(tmp, name, duration, extra='', margin='conformal'):
    path = tmp / f'{name}.yaml'
    path.write_text(SCENARIO.format(duration=duration, extra=extra, margin=margin))
    out = tmp / name
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=300)
    assert proc.returncode in (0, 1), proc.stderr
    return out


def messages(recording, topic):
    factory = DecoderFactory()
    with open(recording, 'rb') as f:
        return [factory.decoder_for(c.message_encoding, s)(m.data)
                for s, c, m in make_reader(f).iter_messages(topics=[topic],
                                                            log_time_order=True)]


def stamp(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def leg_scores(recording):
    """Largest perpendicular distance from each leg's line, from /odom and /controller/state."""
    states = {stamp(s): s for s in messages(recording, '/controller/state')}
    stamps = sorted(states)
    answered = {stamp(s) for s in messages(recording, '/safety/status')}
    scores: dict[int, float] = {}
    for odom in messages(recording, '/odom'):
        if stamp(odom) not in answered:       # the run ended before the safety node saw it
            continue
        k = int(np.searchsorted(stamps, stamp(odom)))
        if k == 0:
            continue
        leg = states[stamps[k - 1]]               # the state of the step before
        if leg.d0 <= 0.0:
            continue
        a = np.array([leg.leg_start.x, leg.leg_start.y])
        b = np.array([leg.leg_target.x, leg.leg_target.y])
        p = np.array([odom.pose.pose.position.x, odom.pose.pose.position.y])
        u = (b - a) / np.linalg.norm(b - a)
        d = abs(u[0] * (p - b)[1] - u[1] * (p - b)[0])
        scores[leg.leg_index] = max(scores.get(leg.leg_index, 0.0), d)
    return [scores[i] for i in sorted(scores)]


def test_scores_round_trip_through_the_calibration_file(tmp_path):
    first = run(tmp_path, 'first', 14.0)
    written = json.loads((first / 'calibration.json').read_text())
    expected = leg_scores(first / 'run.mcap')
    assert written['format'] == 'rrtq-margin-calibration' and len(expected) >= 3
    np.testing.assert_allclose(written['scores'], expected, rtol=1e-9, atol=1e-12)
    # A later run starts with those scores in its window, and writes them before its own.
    second = run(tmp_path, 'second', 2.0, f", calibration: {first / 'calibration.json'}")
    status = messages(second / 'run.mcap', '/safety/status')
    assert status[0].samples == len(expected) and status[0].margin_mode == 'conformal'
    again = json.loads((second / 'calibration.json').read_text())['scores']
    assert again[:len(expected)] == written['scores'] and len(again) > len(expected)


def test_learned_bound_starts_from_a_pooled_calibration_and_writes_its_categories(tmp_path):
    """learned_bound, conformal, from a calibration file (docs/margins.md §10): its first
    leg is grown by the first-leg quantile (0.3 m here, not the running max of nothing), a
    leg with a tube by that tube times the published scale -- its category's, 0.5 on the
    prior bound, 0.8 on a refuted level -- the published margin never drops under the leg's
    within it, and the run's file carries each leg's deviation -- recomputed here from /odom
    -- over its recorded tube, in its category, or raw for a leg without one."""
    from rrtq_planner.margins.calibration import Calibration, write_calibration
    cal = tmp_path / 'pooled.json'
    write_calibration(cal, Calibration((), 'test', normalized=(0.5,) * 25, prior=(0.3,) * 25,
                                       refuted=(0.8,) * 25))
    out = run(tmp_path, 'learned', 14.0, f', calibration: {cal}', 'learned_bound')
    status = messages(out / 'run.mcap', '/safety/status')
    legs: dict[int, list] = {}
    for s in status:
        if s.legs == 0:
            continue
        row = legs.setdefault(s.legs, [s.leg_margin, s.leg_tube, s.scale, [], s.leg_refuted])
        row[3].append(s.margin - 0.3)                  # the robot radius of SCENARIO
    rows = [legs[k] for k in sorted(legs)]
    assert rows[0][1] == 0.0 and abs(rows[0][0] - 0.3) < 1e-9
    with_tube = [r for r in rows if r[1] > 0.0]
    assert with_tube, 'no leg started with a contracting model'
    for at_start, tube, scale, published, _ in rows:
        assert min(published) >= at_start - 1e-9
        if tube > 0.0:
            assert abs(at_start - scale * tube) <= 1e-9 * max(1.0, at_start)
    # Each category's pooled scale, before its own legs (this short mission need not meet a
    # refuted level; a leg on the prior bound it must).
    on_prior = [r for r in with_tube if not r[4]]
    assert on_prior and abs(on_prior[0][2] - 0.5) < 1e-9
    on_refuted = [r for r in with_tube if r[4]]
    assert not on_refuted or abs(on_refuted[0][2] - 0.8) < 1e-9
    written = json.loads((out / 'calibration.json').read_text())
    assert written['normalized'][:25] == [0.5] * 25 and written['prior'][:25] == [0.3] * 25
    assert written['refuted'][:25] == [0.8] * 25
    deviations = leg_scores(out / 'run.mcap')
    assert len(deviations) == len(rows)
    expected = {key: [d / r[1] for d, r in zip(deviations, rows) if r[1] > 0.0 and r[4] == up]
                for key, up in (('normalized', False), ('refuted', True))}
    expected_prior = [d for d, r in zip(deviations, rows) if r[1] <= 0.0]
    for key, values in expected.items():
        np.testing.assert_allclose(written[key][25:], values, rtol=1e-9)
    np.testing.assert_allclose(written['prior'][25:], expected_prior, rtol=1e-9, atol=1e-12)
