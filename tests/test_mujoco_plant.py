"""plant.model: mujoco — the MuJoCo physics plant against the analytic rover, friction, contact.

The core (rrtq_sim.mujoco_plant) is checked without ROS: free motion equals the exact
zero-order-hold rover (stiffness 0) within the integration error of its RK4 substeps,
Coulomb friction holds a base pushed below its level and lets (F - friction)/m through
above it, an obstacle is a physical contact, and a sequence repeats bit for bit. The
plant in a scenario and in ``rrtq run``: test_mujoco_run.py.
"""

import numpy as np
import pytest

from rrtq_common.world import ObstacleSpec
from rrtq_sim.mujoco_model import SUBSTEPS, BaseParameters, MjcfError, obstacle_pieces
from rrtq_sim.mujoco_plant import MujocoPlant
from rrtq_sim.plant import Plant, rover_matrices

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
