"""The closed loop end to end: planner, safety, learning controller, in both modes."""

import json
import pathlib
import subprocess

import pytest
from mcap.reader import make_reader

from rrtq_bringup.report.run import summarise
from rrtq_bringup.run_data import read_run

ROOT = pathlib.Path(__file__).resolve().parents[1]

LOOP = """
name: loop
seed: 5
bounds: {{x: [-10, 10], y: [-10, 10]}}
start: [-6.0, -6.0]
goal: [{goal}]
duration: {duration}
perception_radius: {perception}
robot_radius: 0.3
plant: {{model: rover, stiffness: 0.0}}
controller:
  variant: nominal
  M: 10.0
  R: 0.02
  initial_gain: [[40, 0, 30, 0], [0, 40, 0, 30]]
  probing_std: 5.0
planner: {{steer_distance: 3.0, iterations_per_step: 20, max_nodes: 800}}
obstacles:
  - {{id: mid, polygon: [[-1, -3], [1, -3], [1, 3], [-1, 3]], appear_at: 2.0}}
{extra}
"""

# Four walls around (6, 5), appearing once the robot is on its way.
RING = """
  - {id: ring_s, polygon: [[4, 3], [8, 3], [8, 3.4], [4, 3.4]], appear_at: 1.0}
  - {id: ring_n, polygon: [[4, 6.6], [8, 6.6], [8, 7], [4, 7]], appear_at: 1.0}
  - {id: ring_w, polygon: [[4, 3], [4.4, 3], [4.4, 7], [4, 7]], appear_at: 1.0}
  - {id: ring_e, polygon: [[7.6, 3], [8, 3], [8, 7], [7.6, 7]], appear_at: 1.0}
"""


def run(tmp, name, mode='composed', goal='6.0, 5.0', duration=90.0, extra='',
        perception=5.0):
    path = tmp / f'{name}.yaml'
    path.write_text(LOOP.format(goal=goal, duration=duration, extra=extra,
                                perception=perception))
    out = tmp / name
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', mode], capture_output=True, text=True, timeout=400)
    return proc, out


def odom(out):
    return [m.data for _, _, m in make_reader(open(out / 'run.mcap', 'rb')).iter_messages(
        topics=['/odom'])]


def test_closed_loop_is_deterministic_across_modes(tmp_path):
    a, out_a = run(tmp_path, 'p', mode='processes', duration=5.0)
    b, out_b = run(tmp_path, 'c', mode='composed', duration=5.0)
    assert a.returncode == b.returncode == 1        # 5 s is too short to arrive: failed
    assert len(odom(out_a)) == 101 and odom(out_a) == odom(out_b)
    topics = read_run(out_a / 'run.mcap').topics
    for topic in ('/plan', '/planner/stats', '/planner/tree', '/safety/status',
                  '/obstacles/augmented', '/controller/state', '/goal_pose'):
        assert topics.get(topic, 0) > 0, topic


def test_reaches_the_goal_without_collision_judged_from_odometry(tmp_path):
    proc, out = run(tmp_path, 'goal')
    assert proc.returncode == 0, proc.stdout + proc.stderr
    live = json.loads((out / 'summary.json').read_text())
    assert live['outcome'] == 'goal_reached' and live['replans'] >= 1
    from rrtq_bringup.run_data import embedded_scenario
    judged = summarise(read_run(out / 'run.mcap'), embedded_scenario(out / 'run.mcap'))
    assert judged['collided'] is False and judged['min_clearance_m'] > 0.0
    assert judged['time_to_goal_s'] is not None


def test_walled_in_goal_fails_at_its_duration_with_a_reason(tmp_path):
    # A wide perception disc: the ring is seen whole a few metres into the run.
    proc, out = run(tmp_path, 'walled', duration=20.0, extra=RING, perception=15.0)
    assert proc.returncode == 1
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['outcome'] == 'duration_elapsed' and summary['collided'] is False
    assert 'no path to the goal' in summary['reason']
    data = read_run(out / 'run.mcap')
    assert data.odom_t[-1] == pytest.approx(20.0)
    # cut off at the step the ring is seen whole (its far walls are behind its near ones:
    # 12-15 s in, by the way the robot goes), then held for the rest
    whole = min(t for t, obstacles in data.detected
                if {'ring_s', 'ring_n', 'ring_w', 'ring_e'} <= {oid for oid, _ in obstacles})
    assert summary['no_path_since_s'] == pytest.approx(whole)
    assert whole < 17.0
    # The robot holds once the goal is cut off: it ends at rest, outside the ring.
    assert abs(data.odom_x[-1, 2]) + abs(data.odom_x[-1, 3]) < 0.2
