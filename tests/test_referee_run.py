"""End to end: a robot pushed out of its bounds, with noisy odometry and a delayed actuator.

One `rrtq run` of an open-loop scenario: a constant force drives the robot east, past an
obstacle, out through the east edge of the bounds. The run must end there, failed
(`out_of_bounds`, exit code 1), judged on the true state; /referee/status must say what
an independent computation on /odom/truth says; the report's path, clearance and time are
the true state's, not the noisy measurement's.
"""

import json
import math
import pathlib
import subprocess

import numpy as np
import pytest
import shapely
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rrtq_bringup.report.run import summarise
from rrtq_bringup.run_data import embedded_scenario, read_run

ROOT = pathlib.Path(__file__).resolve().parents[1]
RADIUS, EAST, DELAY = 0.3, 5.0, 0.25
WALL = [[0, 1.5], [2, 1.5], [2, 2.5], [0, 2.5]]

SCENARIO = f"""
name: out-of-bounds
seed: 3
bounds: {{x: [-5, {EAST}], y: [-5, 5]}}
start: [0.0, 0.0]
goal: [-4.0, 4.0]
duration: 20.0
robot_radius: {RADIUS}
plant:
  model: rover
  stiffness: 0.0
  force_limit: 200.0
  actuation_delay: {DELAY}
  odometry_noise: {{position: 0.05, velocity: 0.05}}
controller:
  variant: open_loop
  forces: [[0.0, 90.0, 0.0]]
obstacles:
  - {{id: wall, polygon: {WALL}}}
"""


def stamp(header):
    return header.stamp.sec + header.stamp.nanosec * 1e-9


@pytest.fixture(scope='module')
def pushed_out(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('referee')
    scenario = tmp / 'out.yaml'
    scenario.write_text(SCENARIO)
    out = tmp / 'run'
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(scenario), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=300)
    decoded: dict[str, list] = {}
    factory = DecoderFactory()
    with open(out / 'run.mcap', 'rb') as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.topic in ('/odom', '/odom/truth', '/referee/status'):
                decode = factory.decoder_for(channel.message_encoding, schema)
                decoded.setdefault(channel.topic, []).append(decode(message.data))
    return proc, out, decoded


def test_leaving_the_bounds_fails_the_run_at_the_first_true_step_outside(pushed_out):
    proc, out, decoded = pushed_out
    assert proc.returncode == 1, proc.stderr
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['outcome'] == 'out_of_bounds' and summary['exit_code'] == 1
    assert summary['success'] is False and summary['collided'] is False
    truth = sorted(decoded['/odom/truth'], key=lambda m: stamp(m.header))
    t = np.array([stamp(m.header) for m in truth])
    x = np.array([[m.pose.pose.position.x, m.pose.pose.position.y] for m in truth])
    outside = np.flatnonzero(x[:, 0] > EAST)
    assert outside.size, 'the robot never left the bounds'
    first = outside[0]
    assert summary['sim_time_s'] == pytest.approx(t[first])
    assert f't={t[first]:.2f} s' in summary['reason']
    assert f'({x[first, 0]:.2f}, {x[first, 1]:.2f})' in summary['reason']
    # The referee's summary is the true path's: its length and its clearance to the wall.
    steps = np.linalg.norm(np.diff(x[:first + 1], axis=0), axis=1).sum()
    assert summary['path_length_m'] == pytest.approx(steps, rel=1e-9)
    wall = shapely.Polygon(WALL)
    gaps = [wall.distance(shapely.Point(p)) - RADIUS for p in x[:first + 1]]
    assert summary['min_clearance_m'] == pytest.approx(min(gaps), abs=1e-9)


def test_the_actuator_acts_after_its_delay(pushed_out):
    _, _, decoded = pushed_out
    truth = sorted(decoded['/odom/truth'], key=lambda m: stamp(m.header))
    at_rest = [m for m in truth if stamp(m.header) <= DELAY + 1e-9]
    moving = [m for m in truth if stamp(m.header) > DELAY + 1e-9]
    assert len(at_rest) == round(DELAY / 0.05) + 1
    assert all(m.pose.pose.position.x == 0.0 and m.twist.twist.linear.x == 0.0
               for m in at_rest)
    assert moving[0].twist.twist.linear.x > 0.0


def test_the_referee_status_is_the_truth_judged_every_step(pushed_out):
    _, _, decoded = pushed_out
    truth = {stamp(m.header): m for m in decoded['/odom/truth']}
    referee = {stamp(m.header): m for m in decoded['/referee/status']}
    assert set(referee) == set(truth) and len(referee) > 40
    wall = shapely.Polygon(WALL)
    left = False
    for t in sorted(truth):
        p = truth[t].pose.pose.position
        status = referee[t]
        assert status.header.frame_id == 'map'
        assert status.nearest_obstacle == 'wall'
        assert status.min_clearance == pytest.approx(
            wall.distance(shapely.Point(p.x, p.y)) - RADIUS, abs=1e-9)
        inside = min(p.x + 5.0, EAST - p.x, p.y + 5.0, 5.0 - p.y)
        expected = inside if inside >= 0.0 else -math.hypot(max(p.x - EAST, 0.0), 0.0)
        assert status.bounds_clearance == pytest.approx(expected, abs=1e-12)
        left = left or p.x > EAST
        assert status.out_of_bounds is left and status.collision is False
    assert left


def test_the_robot_measures_with_noise_and_the_report_judges_the_truth(pushed_out):
    _, out, decoded = pushed_out
    truth = {stamp(m.header): m for m in decoded['/odom/truth']}
    measured = {stamp(m.header): m for m in decoded['/odom']}
    assert set(measured) == set(truth)
    residual = np.array([[measured[t].pose.pose.position.x - truth[t].pose.pose.position.x,
                          measured[t].twist.twist.linear.y - truth[t].twist.twist.linear.y]
                         for t in sorted(truth)])
    assert np.all(residual != 0.0)
    assert all(measured[t].pose.covariance[0] == pytest.approx(0.05 ** 2) for t in measured)
    data = read_run(out / 'run.mcap')
    judged = summarise(data, embedded_scenario(out / 'run.mcap'))
    t, x = data.true_state()
    assert np.array_equal(t, data.odom_t) and not np.array_equal(x, data.odom_x)
    true_length = float(np.linalg.norm(np.diff(x[:, :2], axis=0), axis=1).sum())
    noisy_length = float(np.linalg.norm(np.diff(data.odom_x[:, :2], axis=0), axis=1).sum())
    assert judged['path_length_m'] == pytest.approx(true_length, rel=1e-12)
    assert noisy_length > true_length + 0.5         # 0.05 m of noise per step adds up
    referee = min(m.min_clearance for m in decoded['/referee/status'])
    assert judged['min_clearance_m'] == pytest.approx(referee, abs=1e-9)
