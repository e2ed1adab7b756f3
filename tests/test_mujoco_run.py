"""plant.model: mujoco in a scenario and a run — its keys, the supervisor's contact, rrtq run.

The scenario's MuJoCo keys and their errors, the example scenario, a contact judged as a
collision whichever message comes first, and ``rrtq run`` lock-step: a wall that stops the
base, a run that repeats exactly, the closed loop on the frictionless physics plant
against the rover's, and against Coulomb friction with the opt-in integral action. The
plant alone (rrtq_sim.mujoco_plant): test_mujoco_plant.py.
"""

import pathlib

import numpy as np
import pytest

from rrtq_common.world import ObstacleSpec
from rrtq_sim.plant import rover_matrices

ROOT = pathlib.Path(__file__).resolve().parents[1]
DT = 0.05
BOX = ObstacleSpec('box', np.array([[2.0, -1.0], [3.0, -1.0], [3.0, 1.0], [2.0, 1.0]]))


# -- the scenario keys -------------------------------------------------------------------

SCENARIO = {
    'bounds': {'x': [-10, 10], 'y': [-10, 10]}, 'start': [-5.0, 0.0], 'goal': [5.0, 0.0],
    'robot_radius': 0.3,
    'plant': {'model': 'mujoco', 'mass': 30.0, 'damping': 10.0, 'friction': 0.2},
    'obstacles': [{'id': 'box', 'polygon': [[-1, -1], [1, -1], [1, 1], [-1, 1]]}],
}
GOOD_MJCF = """<mujoco><worldbody><body name="base">
  <joint name="x" type="slide" axis="1 0 0"/><joint name="y" type="slide" axis="0 1 0"/>
  <geom type="cylinder" size="0.3 0.1" mass="12"/></body></worldbody>
  <actuator><motor name="fx" joint="x"/><motor name="fy" joint="y"/></actuator></mujoco>"""


def scenario(tmp_path, **plant):
    from rrtq_bringup.scenario import parse_scenario
    data = {**SCENARIO, 'plant': {'model': 'mujoco', **plant}}
    return parse_scenario(data, str(tmp_path / 'sc.yaml'))


def test_plant_model_mujoco_loads_with_its_keys(tmp_path):
    from rrtq_sim.plant import PlantModel
    sc = scenario(tmp_path, mass=30.0, damping=10.0, friction=0.2)
    p = sc.plant
    assert p.model is PlantModel.MUJOCO and p.mjcf is None
    assert (p.mass, p.damping, p.friction, p.stiffness) == (30.0, 10.0, 0.2, 0.0)
    a, b = rover_matrices(30.0, 0.0, 10.0)
    assert np.array_equal(p.A, a) and np.array_equal(p.B, b)


def test_plant_mjcf_is_read_relative_to_the_scenario_and_gives_the_mass(tmp_path):
    (tmp_path / 'robot.xml').write_text(GOOD_MJCF)
    p = scenario(tmp_path, mjcf='robot.xml').plant
    assert p.mjcf == str(tmp_path / 'robot.xml') and p.mass == pytest.approx(12.0)


@pytest.mark.parametrize('plant, key, words', [
    ({'mjcf': 'gone.xml'}, 'plant.mjcf', 'no such file'),
    ({'mjcf': 'bad.xml'}, 'plant.mjcf', 'not a valid MJCF'),
    ({'mjcf': 'robot.xml', 'friction': 3.0}, 'plant.friction', 'the MJCF file defines it'),
    ({'stiffness': 20.0}, 'plant.stiffness', ''),
    ({'friction': -1.0}, 'plant.friction', ''),
])
def test_bad_mujoco_keys_name_the_file_and_the_key(tmp_path, plant, key, words):
    from rrtq_bringup.scenario import ScenarioError
    (tmp_path / 'robot.xml').write_text(GOOD_MJCF)
    (tmp_path / 'bad.xml').write_text('<mujoco><worldbody><body')
    with pytest.raises(ScenarioError) as err:
        scenario(tmp_path, **plant)
    assert err.value.key == key and err.value.file == str(tmp_path / 'sc.yaml')
    assert words in str(err.value)


def test_a_disturbance_with_position_rows_is_refused(tmp_path):
    from rrtq_bringup.scenario import ScenarioError, parse_scenario
    data = {**SCENARIO, 'disturbance': {'model': 'constant', 'F': [[1], [0], [0], [1]]}}
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data, str(tmp_path / 'sc.yaml'))
    assert err.value.key == 'disturbance.F'


def test_rrtq_run_exits_2_on_a_missing_mjcf_naming_the_file_and_the_key(tmp_path, root):
    import subprocess
    import yaml
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump({**SCENARIO, 'plant': {'model': 'mujoco',
                                                          'mjcf': 'nope.xml'}}))
    out = tmp_path / 'out'
    proc = subprocess.run([str(root / 'scripts/rrtq'), 'run', str(path), '--out', str(out)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert str(path) in proc.stderr and 'plant.mjcf' in proc.stderr and 'nope.xml' in proc.stderr
    assert not out.exists()


def test_the_example_scenario_loads(root):
    from rrtq_bringup.scenario import load_scenario
    from rrtq_sim.plant import PlantModel
    sc = load_scenario(root / 'scenarios' / 'mujoco_friction.yaml')
    assert sc.plant.model is PlantModel.MUJOCO and sc.plant.friction > 0.0


# -- the supervisor's judgement of a contact ---------------------------------------------------

def _monitor():
    from rrtq_bringup.mission import MissionConfig, MissionMonitor
    from rrtq_common.world import TrueObstacles
    config = MissionConfig(goal=(50.0, 0.0), duration=100.0, robot_radius=0.3,
                           bounds=((-100.0, 100.0), (-100.0, 100.0)), dt=DT)
    return MissionMonitor(config, TrueObstacles([BOX], 0.3))


@pytest.mark.parametrize('contact_first', [True, False])
def test_a_contact_ends_the_run_as_a_collision_whichever_message_comes_first(contact_first):
    """The step at t = 0.1 touched the box (and its odometry overlaps it by 2 mm)."""
    from rrtq_bringup.mission import Outcome
    mon = _monitor()
    mon.on_odometry(0.05, np.array([1.0, 0.0]))
    if contact_first:
        mon.on_contact(0.1, ('box',), 1)
        assert mon.outcome is Outcome.RUNNING          # waits for its odometry
        mon.on_odometry(0.1, np.array([1.702, 0.0]))
    else:
        mon.on_odometry(0.1, np.array([1.702, 0.0]))
        mon.on_contact(0.1, ('box',), 1)
    assert mon.outcome is Outcome.COLLISION and mon.collided and not mon.success
    assert mon.reason.startswith('physical contact with box at t=0.10 s')
    assert mon.summary()['contact_steps'] == 1 and mon.t == pytest.approx(0.1)


# -- rrtq run, lock-step ------------------------------------------------------------------

HIT = """
name: mujoco-hit
seed: 3
bounds: {x: [-5, 8], y: [-5, 5]}
start: [0.0, 0.0]
goal: [-4.0, 4.0]
duration: 10.0
robot_radius: 0.3
plant:
  model: mujoco
  mass: 40.0
  damping: 10.0
  friction: 0.05
  force_limit: 200.0
  actuation_delay: 0.1
  odometry_noise: {position: 0.01, velocity: 0.01}
controller:
  variant: open_loop
  forces: [[0.0, 120.0, 0.0]]
obstacles:
  - {id: wall, polygon: [[3, -2], [4, -2], [4, 2], [3, 2]]}
"""


def _recorded(path, topics):
    from mcap.reader import make_reader
    out = {t: [] for t in topics}
    with open(path, 'rb') as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic in out:
                out[channel.topic].append(message.data)
    return out


@pytest.fixture(scope='module')
def two_runs(tmp_path_factory):
    import subprocess
    tmp = tmp_path_factory.mktemp('mujoco_run')
    path = tmp / 'hit.yaml'
    path.write_text(HIT)
    runs = []
    for k in range(2):
        out = tmp / f'run{k}'
        proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                               '--mode', 'composed'], capture_output=True, text=True,
                              timeout=300)
        runs.append((proc, out))
    return runs


def test_driving_into_a_wall_ends_the_run_as_a_physical_contact(two_runs):
    import json
    from mcap_ros2.decoder import DecoderFactory
    from mcap.reader import make_reader
    proc, out = two_runs[0]
    assert proc.returncode == 1, proc.stderr
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['outcome'] == 'collision' and summary['collided'] is True
    assert summary['reason'].startswith('physical contact with wall at t=')
    assert summary['contact_steps'] >= 1
    decoded = {}
    factory = DecoderFactory()
    with open(out / 'run.mcap', 'rb') as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.topic in ('/plant/contact', '/odom/truth'):
                decode = factory.decoder_for(channel.message_encoding, schema)
                decoded.setdefault(channel.topic, []).append(decode(message.data))
    contact = decoded['/plant/contact'][0]
    assert list(contact.obstacles) == ['wall'] and contact.contact_steps == 1
    t_contact = contact.header.stamp.sec + contact.header.stamp.nanosec * 1e-9
    assert f't={t_contact:.2f} s' in summary['reason']
    # the truth at the contact: the disc (0.3 m) at the wall's face x = 3, millimetres in
    last = max(decoded['/odom/truth'], key=lambda m: (m.header.stamp.sec, m.header.stamp.nanosec))
    assert 2.65 < last.pose.pose.position.x < 2.75


def test_a_run_repeats_exactly(two_runs):
    (p0, out0), (p1, out1) = two_runs
    assert p0.returncode == p1.returncode == 1
    topics = ('/odom', '/odom/truth', '/plant/contact')
    a, b = _recorded(out0 / 'run.mcap', topics), _recorded(out1 / 'run.mcap', topics)
    assert len(a['/odom']) > 20
    for topic in topics:
        assert sorted(a[topic]) == sorted(b[topic]), topic


LOOP = """
name: mujoco-loop
seed: 1
bounds: {x: [-8, 8], y: [-8, 8]}
start: [-5.0, -1.0]
goal: [5.0, 1.0]
duration: 90.0
robot_radius: 0.2
plant: PLANT
obstacles:
  - {id: box, polygon: [[-1, -3], [1, -3], [1, 0.5], [-1, 0.5]], known: true}
"""


def test_closed_loop_on_the_frictionless_physics_plant_is_the_rovers_run(tmp_path):
    """Planner, learning controller and safety node around a box, lock-step: on MuJoCo without
    friction the mission is the rover's (stiffness 0) to the integration error — the same
    time to the goal, the same replans, the path within 1e-3 m (measured: 2e-6 m)."""
    import json
    import subprocess
    summaries = {}
    for name, plant in (('mujoco', '{model: mujoco, mass: 40.0, damping: 45.0}'),
                        ('rover', '{model: rover, mass: 40.0, stiffness: 0.0, damping: 45.0}')):
        path = tmp_path / f'{name}.yaml'
        path.write_text(LOOP.replace('PLANT', plant))
        out = tmp_path / name
        proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                               '--mode', 'composed'], capture_output=True, text=True,
                              timeout=300)
        assert proc.returncode == 0, proc.stderr
        summaries[name] = json.loads((out / 'summary.json').read_text())
    mj, rover = summaries['mujoco'], summaries['rover']
    assert mj['outcome'] == 'goal_reached' and mj['contact_steps'] == 0
    assert mj['time_to_goal_s'] == rover['time_to_goal_s'] and mj['replans'] == rover['replans']
    assert mj['path_length_m'] == pytest.approx(rover['path_length_m'], abs=1e-3)
    assert mj['min_clearance_m'] == pytest.approx(rover['min_clearance_m'], abs=1e-3)


def test_from_the_defaults_the_robot_reaches_its_goal_against_coulomb_friction(tmp_path):
    """The same mission at μ = 0.1 (39 N per axis on the 40 kg base), from the controller's
    defaults: the zero initial gain and its 20 N of probing never break the friction, and a
    state feedback stops wherever K x̄ no longer exceeds it (with
    ``controller.integral_action: false`` not at the goal in 200 s, measured). The retried
    leg's integral action (on by default) takes the robot there: goal, no physical contact, no command
    beyond the 1000 N limit (read from the recording with mcap-ros2-support's decoder), and
    the guard's held_short in /controller/state."""
    import json
    import subprocess

    from mcap_ros2.reader import read_ros2_messages
    path = tmp_path / 'friction.yaml'
    path.write_text(LOOP.replace('PLANT', '{model: mujoco, mass: 40.0, damping: 45.0, '
                                 'friction: 0.1}').replace('duration: 90.0', 'duration: 150.0'))
    out = tmp_path / 'run'
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['outcome'] == 'goal_reached' and summary['contact_steps'] == 0
    largest, held = 0.0, 0
    for m in read_ros2_messages(str(out / 'run.mcap'), topics=['/cmd_force', '/controller/state']):
        if m.channel.topic == '/cmd_force':
            f = m.ros_msg.wrench.force
            largest = max(largest, abs(f.x), abs(f.y))
        else:
            held += 'held_short' in m.ros_msg.policy_event
    assert 0.0 < largest <= 1000.0 and held >= 1
