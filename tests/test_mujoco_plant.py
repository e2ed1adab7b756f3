"""plant.model: mujoco — the MuJoCo physics plant against the analytic rover, friction, contact.

The core (rrtq_sim.mujoco_plant) is checked without ROS: free motion equals the exact
zero-order-hold rover (stiffness 0) within the integration error of its RK4 substeps,
Coulomb friction holds a base pushed below its level and lets (F - friction)/m through
above it, an obstacle is a physical contact, and a sequence repeats bit for bit.
"""

import pathlib

import numpy as np
import pytest

from rrtq_common.world import ObstacleSpec
from rrtq_sim.mujoco_model import SUBSTEPS, BaseParameters, MjcfError, obstacle_pieces
from rrtq_sim.mujoco_plant import MujocoPlant
from rrtq_sim.plant import Plant, rover_matrices

ROOT = pathlib.Path(__file__).resolve().parents[1]
DT = 0.05
F_PAPER = [[0.0], [0.0], [-1.0], [1.0]]
BOX = ObstacleSpec('box', np.array([[2.0, -1.0], [3.0, -1.0], [3.0, 1.0], [2.0, 1.0]]))
# non-convex: an L, whose notch must stay free
ELL = ObstacleSpec('ell', np.array([[0.0, 5.0], [4.0, 5.0], [4.0, 9.0], [3.0, 9.0],
                                    [3.0, 6.0], [0.0, 6.0]]))


def plant(mass=40.0, damping=45.0, friction=0.0, radius=0.3, obstacles=(), limit=1000.0):
    return MujocoPlant(list(obstacles), DT, limit, F_PAPER,
                       base=BaseParameters(mass, damping, friction, radius))


def test_free_motion_matches_the_exact_rover_within_rk4_error():
    """200 steps of a seeded random force and disturbance, against expm of the rover.

    RK4's local error is O(h^5) per substep of h = Δt/10 = 5 ms: with |x''| ~ 3 m/s^2 and
    c/m ~ 1, some 1e-11 m over the run; a tolerance of 1e-8 m (m/s) leaves room for
    rounding and still fails any first-order integrator (Euler is ~1e-3 off here).
    """
    rng = np.random.default_rng(32)
    forces = rng.uniform(-150.0, 150.0, (200, 2))
    disturbances = rng.normal(0.0, 1.0, (200, 1))
    a, b = rover_matrices(40.0, 0.0, 45.0)
    exact = Plant(a, b, F_PAPER, DT, 1000.0)
    mj = plant()
    x_exact = x_mj = np.array([1.0, -2.0, 0.0, 0.0])
    worst = 0.0
    for u, d in zip(forces, disturbances):
        x_exact = exact.step(x_exact, u, d, np.zeros(2))
        x_mj = mj.step(x_mj, u, d)
        worst = max(worst, float(np.max(np.abs(x_mj - x_exact))))
    assert np.max(np.abs(x_exact[:2] - [1.0, -2.0])) > 0.5     # it went somewhere
    assert worst < 1e-8, worst
    assert mj.contact_steps == 0 and mj.contact == ()
    assert mj.substeps == SUBSTEPS and mj.mass == pytest.approx(40.0)


def test_saturation_applies_the_force_limit():
    a, b = rover_matrices(40.0, 0.0, 45.0)
    exact = Plant(a, b, F_PAPER, DT, 50.0)
    mj = plant(limit=50.0)
    x0 = np.zeros(4)
    assert np.allclose(mj.step(x0, [500.0, -80.0], None), exact.step(x0, [50.0, -50.0], None,
                                                                     np.zeros(2)), atol=1e-9)


def test_coulomb_friction_holds_below_its_level_and_subtracts_above():
    """friction = 20 N per axis: 15 N and -19 N leave the base at rest for 5 s; 60 N accelerates
    it at (60 - 20)/m (no damping)."""
    mj = plant(mass=40.0, damping=0.0, friction=20.0)
    x = np.zeros(4)
    for _ in range(100):
        x = mj.step(x, [15.0, -19.0], None)
    assert np.max(np.abs(x)) < 1e-9, x
    for _ in range(4):
        x = mj.step(x, [60.0, 0.0], None)
    t = 4 * DT
    assert x[2] == pytest.approx((60.0 - 20.0) / 40.0 * t, rel=1e-3)
    assert x[0] == pytest.approx(0.5 * (60.0 - 20.0) / 40.0 * t**2, rel=1e-3)
    assert abs(x[1]) < 1e-9 and abs(x[3]) < 1e-9


def test_disturbance_is_an_external_force_of_mass_times_acceleration():
    """d = 0.5 through F's column [0, 0, -1, 1]: the base accelerates at (-0.5, 0.5) m/s^2."""
    mj = plant(mass=120.0, damping=0.0)
    x = mj.step(np.zeros(4), [0.0, 0.0], [0.5])
    assert x[2:] == pytest.approx([-0.5 * DT, 0.5 * DT], rel=1e-9)


def test_driving_into_a_box_is_a_contact_that_stops_the_base():
    mj = plant(obstacles=[BOX])
    x = np.zeros(4)
    first = None
    for k in range(200):
        x = mj.step(x, [200.0, 0.0], None)
        if mj.contact and first is None:
            first = k
            assert mj.contact == ('box',)
    assert first is not None
    # the base's disc (0.3 m) rests against the face x = 2, a few mm deep at most
    assert x[0] == pytest.approx(1.7, abs=0.01) and abs(x[2]) < 1e-3
    assert mj.contact_steps == 200 - first


def test_an_absent_obstacle_is_not_physical():
    mj = plant(obstacles=[BOX])
    mj.set_present([])
    x = np.zeros(4)
    for _ in range(40):
        x = mj.step(x, [200.0, 0.0], None)
    assert x[0] > 3.5 and mj.contact_steps == 0


def test_obstacles_come_and_go_with_the_truth_the_referee_keeps():
    """The simulation switches the plant's geoms to what exists before each step: a wall
    that vanishes at 0.2 s is driven through, one that appears at 0.5 s is hit."""
    from rrtq_common.world import TrueObstacles
    from rrtq_sim.plant import SpringAnchor
    from rrtq_sim.simulation import Simulation
    gone = ObstacleSpec('gone', np.array([[1.0, -1.0], [1.5, -1.0], [1.5, 1.0], [1.0, 1.0]]),
                        vanish_at=0.2)
    late = ObstacleSpec('late', np.array([[3.0, -1.0], [4.0, -1.0], [4.0, 1.0], [3.0, 1.0]]),
                        appear_at=0.5)
    mj = plant(damping=0.0, obstacles=[gone, late])
    sim = Simulation(mj, [0.0, 0.0], SpringAnchor.WORLD_ORIGIN, 0.0,
                     truth=TrueObstacles([gone, late], 0.3))
    sim.hold_force([200.0, 0.0])
    touched = []
    for _ in range(40):
        sim.advance()
        if sim.contact:
            touched.append((sim.now_ns * 1e-9, sim.contact))
    assert touched and {c for _, c in touched} == {('late',)}
    # free flight at 5 m/s^2 puts the disc's edge at x = 3 at t = sqrt(2 * 2.7 / 5) = 1.04 s
    assert touched[0][0] == pytest.approx(1.05, abs=1e-9)
    assert sim.x[0] == pytest.approx(2.7, abs=0.02)


def test_a_non_convex_obstacle_is_its_triangles_and_its_notch_is_free():
    pieces = obstacle_pieces(ELL.polygon)
    assert len(pieces) > 1
    area = sum(abs((p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1])
                   - (p[1, 1] - p[0, 1]) * (p[2, 0] - p[0, 0])) / 2 for p in pieces)
    assert area == pytest.approx(4.0 + 3.0)            # the L's: 4 x 1 + 1 x 3
    mj = plant(radius=0.2, obstacles=[ELL])
    # from inside the notch (x < 3, y > 6) straight up: nothing there
    x = np.array([1.5, 6.5, 0.0, 0.0])
    for _ in range(30):
        x = mj.step(x, [0.0, 100.0], None)
    assert x[1] > 7.0 and mj.contact_steps == 0
    # then right, into the L's upright arm (x in [3, 4])
    for _ in range(60):
        x = mj.step(x, [300.0, 0.0], None)
    # pressed at 300 N, MuJoCo's soft contact gives way by under 2 cm
    assert mj.contact == ('ell',) and 2.8 <= x[0] < 2.82


def test_a_run_repeats_bit_for_bit():
    rng = np.random.default_rng(5)
    forces = rng.uniform(-400.0, 400.0, (150, 2))
    runs = []
    for _ in range(2):
        mj = plant(friction=10.0, obstacles=[BOX, ELL])
        x = np.zeros(4)
        states = []
        for u in forces:
            x = mj.step(x, u, [0.3])
            states.append(x)
        runs.append((np.array(states), mj.contact_steps))
    assert runs[0][1] == runs[1][1]
    assert np.array_equal(runs[0][0], runs[1][0])


def test_user_mjcf_with_named_actuators_and_a_free_base(tmp_path):
    """A user's model: a free-jointed sphere on a floor, actuators fx/fy as site forces."""
    path = tmp_path / 'ball.xml'
    path.write_text("""<mujoco>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="50 50 0.1" friction="0 0 0"/>
    <body name="base" pos="0 0 0.25">
      <freejoint/>
      <geom type="sphere" size="0.25" mass="10" friction="0 0 0"/>
      <site name="c"/>
    </body>
  </worldbody>
  <actuator>
    <general name="fx" site="c" gear="1 0 0 0 0 0"/>
    <general name="fy" site="c" gear="0 1 0 0 0 0"/>
  </actuator>
</mujoco>""")
    mj = MujocoPlant([BOX], DT, 1000.0, F_PAPER, mjcf=str(path))
    assert mj.mass == pytest.approx(10.0)
    x = mj.step(np.zeros(4), [10.0, 0.0], None)
    assert x[2] == pytest.approx(1.0 * DT, rel=0.05)      # 10 N on 10 kg
    for _ in range(100):
        x = mj.step(x, [50.0, 0.0], None)
    assert mj.contact_steps > 0 and x[0] < 2.0


@pytest.mark.parametrize('text, words', [
    (None, 'no such file'),
    ('<mujoco><worldbody><body', 'not a valid MJCF'),
    ('<mujoco><worldbody><body name="base"><freejoint/><geom size="0.1"/></body></worldbody>'
     '</mujoco>', "no actuator named 'fx'"),
])
def test_a_bad_mjcf_file_is_refused_naming_it(tmp_path, text, words):
    path = tmp_path / 'robot.xml'
    if text is not None:
        path.write_text(text)
    with pytest.raises(MjcfError, match=words) as err:
        MujocoPlant([], DT, 1000.0, F_PAPER, mjcf=str(path))
    assert str(path) in str(err.value)


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


def test_the_friction_coefficient_is_mu_m_g_per_axis():
    # The scenario's friction is the dimensionless coefficient; the joints resist mu m g:
    # mu = 0.05 on 40 kg is 19.62 N, which holds 19 N and lets 21 N through at (21 - F_c)/m.
    from rrtq_sim.mujoco_model import coulomb_force
    assert coulomb_force(0.1, 40.0) == pytest.approx(39.24)
    level = coulomb_force(0.05, 40.0)
    mj = plant(mass=40.0, damping=0.0, friction=level)
    x = np.zeros(4)
    for _ in range(20):
        x = mj.step(x, [19.0, -19.0], None)
    assert np.max(np.abs(x)) < 1e-9, x
    x = mj.step(x, [21.0, 0.0], None)
    assert x[2] == pytest.approx((21.0 - level) / 40.0 * DT, rel=1e-3)


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
