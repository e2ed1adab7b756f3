"""Integral action on a leg held short of its waypoint (rrtq_controller.held_short).

Ground truth that does not come from the code under test: the steady offset of a state
feedback under a steady push, F_d / K_p, with K the rover's Riccati gain from scipy; a
Coulomb-friction rover integrated here in 1 ms substeps.
"""

import math

import numpy as np
from scipy.linalg import solve_continuous_are

from rrtq_controller.config import ControllerConfig
from rrtq_controller.driver import LearningDriver
from rrtq_controller.guard import PolicyEvent, Sensing
from rrtq_controller.held_short import HeldShort
from rrtq_controller.q_learning import QLearningController
from rrtq_testing import controller_reference as ref

DT, T, RHO = 0.05, 10.0, 0.15
MASS, DAMPING, LIMIT = 40.0, 45.0, 1000.0


def _riccati_gain() -> np.ndarray:
    A, B = ref.rover(mass=MASS, stiffness=0.0, damping=DAMPING)
    P = solve_continuous_are(A, B, 10.0 * np.eye(4), 0.02 * np.eye(2))
    return np.linalg.solve(0.02 * np.eye(2), B.T @ P)


def _coulomb_step(x: np.ndarray, u: np.ndarray, friction: float) -> np.ndarray:
    """One Δt of the rover with Coulomb friction per axis (stick below it), 1 ms substeps."""
    x = x.copy()
    h = 0.001
    for _ in range(int(round(DT / h))):
        for i in range(2):
            v = x[2 + i]
            if v == 0.0 and abs(u[i]) <= friction:
                continue                                  # stuck
            drive = u[i] - DAMPING * v - friction * (np.sign(v) if v != 0.0 else np.sign(u[i]))
            v_new = v + h * drive / MASS
            x[2 + i] = 0.0 if v != 0.0 and np.sign(v_new) != np.sign(v) else v_new
            x[i] += h * x[2 + i]
    return x


def _fly(step, policy, x0, integral: bool, horizons: int = 6):
    """Legs toward the origin as RRT-QX poses them: after a horizon short of the window, a
    new leg toward the same waypoint from where the robot stands. Returns (entered at s or
    None, final state, largest integral force, largest |u|)."""
    held = HeldShort(2, RHO, T, DT, LIMIT if integral else math.inf)
    x, t0 = np.asarray(x0, dtype=float), 0.0
    held.start_leg(x, retry=False)
    d0, biggest, umax = float(np.linalg.norm(x)), 0.0, 0.0
    for k in range(int(horizons * T / DT)):
        t = k * DT
        if t - t0 >= T - 0.5 * DT:
            t0, d0 = t, float(np.linalg.norm(x))
            held.start_leg(x, retry=True)
        if float(np.linalg.norm(x)) <= RHO * d0:
            return t, x, biggest, umax
        extra = held(x)
        u = np.clip(policy(x) + extra, -LIMIT, LIMIT)
        biggest = max(biggest, float(np.linalg.norm(extra)))
        umax = max(umax, float(np.abs(u).max()))
        x = step(x, u)
    return None, x, biggest, umax


def test_under_a_steady_push_the_optimal_feedback_stops_short_and_integral_action_enters():
    """The field bump's failure: the Riccati gain holds the rover F_d / K_p from its
    waypoint for ever; the retried leg's integral action takes it into its window, with a
    force of about the push, never the actuator's limit."""
    K = _riccati_gain()
    push = np.array([-28.0, 0.0])                         # N, away from a target at the origin
    plant = ref.Plant(*ref.rover(mass=MASS, stiffness=0.0, damping=DAMPING), DT)

    def step(x, u):
        return plant.step(x, u + push)

    x0 = [-5.0, 0.0, 0.0, 0.0]
    entered, x_end, _, _ = _fly(step, lambda x: -K @ x, x0, integral=False)
    assert entered is None
    offset = np.linalg.solve(K[:, :2], push)              # where K_p x̄ balances the push
    assert np.allclose(x_end[:2], offset, atol=0.02 * np.linalg.norm(offset))
    assert np.linalg.norm(offset) > RHO * np.linalg.norm(x0)          # never in its window

    entered, x_end, biggest, umax = _fly(step, lambda x: -K @ x, x0, integral=True)
    assert entered is not None and entered < 3 * T        # within the first two retries
    assert 0.5 * np.linalg.norm(push) < biggest < 2.0 * np.linalg.norm(push)
    assert umax <= LIMIT


def test_a_zero_gain_held_by_coulomb_friction_breaks_free_without_winding_up():
    """The MuJoCo plant at μ = 0.1 (39 N per axis on 40 kg): a zero gain (and probing below
    the friction) never moves the robot; the retried leg's force grows until it does and
    stops growing then: at most the friction plus what carries the robot at the speed the
    leg needs against its damping, plus the ramp over one time constant m / c."""
    friction = 0.1 * MASS * 9.81

    def step(x, u):
        return _coulomb_step(x, u, friction)

    x0 = [-5.0, 0.0, 0.0, 0.0]
    entered, x_end, _, _ = _fly(step, lambda x: np.zeros(2), x0, integral=False, horizons=3)
    assert entered is None and np.allclose(x_end, x0)
    entered, _, biggest, umax = _fly(step, lambda x: np.zeros(2), x0, integral=True, horizons=3)
    assert entered is not None and entered < 3 * T       # in the second retry at the latest
    rate = LIMIT / T
    needed = (np.linalg.norm(x0) * (1 - RHO)) / T
    assert friction < biggest <= friction + DAMPING * needed + rate * MASS / DAMPING
    assert umax <= LIMIT


def test_friction_per_axis_is_broken_on_each_axis_and_the_robot_keeps_to_its_line():
    """Friction per axis (MuJoCo's planar base: a square): a force grown along the line
    breaks the axis it has more of first; held while the robot moves *at all*, it would
    stop growing there and slide the robot along that axis alone, off its line (MuJoCo
    mu = 0.1, seed 0: the line watch braked it 0.26, 0.63 and 1.0 m off in the first 84 s,
    each brake dropping the force). Held per axis, the stuck axis goes on growing until it
    breaks too, and the robot keeps near its line."""
    friction = 0.1 * MASS * 9.81

    def step(x, u):
        return _coulomb_step(x, u, friction)

    x0 = np.array([-5.0, -3.0, 0.0, 0.0])
    across = np.array([3.0, -5.0]) / math.hypot(3.0, 5.0)    # normal to the line to the origin
    held = HeldShort(2, RHO, T, DT, LIMIT)
    held.start_leg(x0, retry=True)
    x, widest = x0.copy(), 0.0
    for _ in range(int(T / DT)):                          # one leg, a retry
        x = step(x, np.clip(held(x), -LIMIT, LIMIT))
        widest = max(widest, abs(float(x[:2] @ across)))
    # both axes broke free and the robot goes toward its target (2.3 m of 5.8 in the leg,
    # from rest and zero force), leaving its line by what the first axis covers before
    # the second breaks, centimetres (1.3 m with the force held while the robot moves)
    assert np.linalg.norm(x0[:2]) - np.linalg.norm(x[:2]) > 2.0
    assert np.all(np.abs(x[2:]) > 0.1)
    assert widest < 0.1


def test_a_leg_that_is_no_retry_gets_no_force_and_a_new_waypoint_drops_it():
    held = HeldShort(2, RHO, T, DT, LIMIT)
    held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=False)
    for _ in range(100):                                  # at rest, far from its target
        assert not held(np.array([-5.0, 0.0, 0.0, 0.0])).any()
    held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=True)
    for _ in range(10):
        force = held(np.array([-5.0, 0.0, 0.0, 0.0]))
    # toward the target, at the rate, from the second step (the first force shows then)
    assert np.allclose(force, [9 * LIMIT / T * DT, 0.0])
    held.start_leg(np.array([3.0, 0.0, 0.0, 0.0]), retry=False)
    assert not held(np.array([3.0, 0.0, 0.0, 0.0])).any()
    assert not HeldShort(2, RHO, T, DT, math.inf).rate        # no limit: no integral action


def test_the_force_holds_while_the_robot_makes_progress_or_speeds_up():
    held = HeldShort(2, RHO, T, DT, LIMIT)
    held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=True)
    assert not held(np.array([-5.0, 0.0, 0.0, 0.0])).any()      # nothing has shown yet
    f0 = held(np.array([-5.0, 0.0, 0.0, 0.0])).copy()
    assert f0[0] > 0.0
    # fast enough toward the target to enter its window in the time left: no growth
    assert np.allclose(held(np.array([-5.0, 0.0, 1.0, 0.0])), f0)
    # slower than it needs and slowing down: it grows
    f1 = held(np.array([-5.0, 0.0, 0.1, 0.0])).copy()
    assert f1[0] > f0[0]
    # as slow, but speeding up fast enough to reach the speed it needs in the time left
    assert np.allclose(held(np.array([-5.0, 0.0, 0.15, 0.0])), f1)
    # speeding up too slowly to matter (a creep toward an asymptote): it grows
    f2 = held(np.array([-5.0, 0.0, 0.1501, 0.0])).copy()
    assert f2[0] > f1[0]
    # carried away from its target (a periodic push swinging it), or across: not held
    assert np.allclose(held(np.array([-5.0, 0.0, -0.8, 0.0])), f2)
    assert np.allclose(held(np.array([-5.0, 0.0, -0.8, 0.0])), f2)
    assert np.allclose(held(np.array([-5.0, 0.0, 0.0, 0.6])), f2)


def test_past_its_target_the_force_keeps_no_part_away_from_it():
    """Friction holds a robot that overshot as it held it short: a force still pushing on
    would have to unwind through twice the friction before the robot comes back (seen at
    μ = 0.3: ±150 N hunting around the goal); its part away from the target is dropped."""
    held = HeldShort(2, RHO, T, DT, LIMIT)
    held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=True)
    for _ in range(20):
        held(np.array([-5.0, 0.0, 0.0, 0.0]))
    assert held.force[0] > 50.0
    force = held(np.array([0.5, 0.3, 0.0, 0.0]))     # past it: the target is at -x̄
    toward = -np.array([0.5, 0.3]) / np.linalg.norm([0.5, 0.3])
    assert float(force @ toward) >= -1e-12
    assert abs(force[1]) > 0.0                          # the part across it is kept


def test_under_odometry_noise_a_robot_at_rest_is_still_held_and_the_force_grows():
    """σ_v = 0.05 m/s: the speed-up test allows for what noise adds to a speed, so a robot
    at rest is not read as speeding up (the force grows on most steps)."""
    rng = np.random.default_rng(0)
    held = HeldShort(2, RHO, T, DT, LIMIT, sensing=Sensing(velocity_std=0.05))
    held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=True)
    for _ in range(100):
        x = np.array([-5.0, 0.0, *rng.normal(0.0, 0.05, 2)])
        force = held(x)
    assert force[0] > 0.9 * 100 * LIMIT / T * DT


def test_under_odometry_noise_a_robot_moving_as_fast_as_it_needs_is_not_held():
    """σ_v = 0.05 m/s, the robot moving toward its target at the speed that reaches the
    window in the time left: an axis counts as held only where its speed falls short by
    more than noise explains (one-sided, 1 %: about 1 of its 100 steps; more than 5 has
    probability 5e-4). Read as exact, a third of its steps count as held and the force
    grows on them (the leg cost the noisy robot side paid: last ten 1.99 on a seed that
    flies 1.00 with the allowance)."""
    def grown_steps(sensing: Sensing) -> int:
        rng = np.random.default_rng(1)
        held = HeldShort(2, RHO, T, DT, LIMIT, sensing=sensing)
        held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=True)
        grew, before, position = 0, 0.0, -5.0
        for k in range(100):
            needed = (abs(position) - held.window) / (T - k * DT)
            x = np.array([position, 0.0, needed + rng.normal(0.0, 0.05), rng.normal(0.0, 0.05)])
            force = held(x, time_left=T - k * DT)
            grew += force[0] > before
            before = force[0]
            position += needed * DT
        return grew

    assert grown_steps(Sensing(velocity_std=0.05)) <= 5
    assert grown_steps(Sensing()) >= 30        # the same noise, read as exact: held


def test_the_needed_speed_is_the_one_that_reaches_the_window_in_the_time_left():
    """A robot that would reach the window in one more horizon is not held at the leg's
    start, and is held with a tenth of the horizon left (a speed that only enters the
    window after the horizon: each leg ran its horizon, and every retry's window was
    smaller, on the MuJoCo plant with friction)."""
    held = HeldShort(2, RHO, T, DT, LIMIT)
    held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=True)
    speed = (5.0 - held.window) / T * 1.05
    x = np.array([-5.0, 0.0, speed, 0.0])
    for _ in range(5):
        force = held(x, time_left=T)
    assert force[0] == 0.0
    for _ in range(5):
        force = held(x, time_left=0.1 * T)
    assert force[0] > 0.0


def _walk(integral_action: bool, seconds: float = 60.0):
    """The driver on the rover under a 28 N push against its first leg (as the field
    bump's), its actor held at the Riccati gain: the waypoints it reached, the largest
    |u| and how often the guard said held_short."""
    K = _riccati_gain()
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, initial_gain=K, alpha_a=1e-9,
                              probing_std=0.0, force_limit=LIMIT,
                              integral_action=integral_action)
    driver = LearningDriver(config, 4, 2, 0, np.random.default_rng(0))
    plant = ref.Plant(*ref.rover(mass=MASS, stiffness=0.0, damping=DAMPING), DT)
    push = np.array([-28.0, 0.0])
    x = np.zeros(4)
    driver.set_plan([[5.0, 0.0], [5.0, 5.0]], x, 0.0)
    reached, umax, held = [], 0.0, 0
    for k in range(int(seconds / DT)):
        out = driver.step(k * DT, x)
        if not reached or reached[-1] != tuple(out.leg_target):
            reached.append(tuple(out.leg_target))
        held += 'held_short' in out.policy_event
        umax = max(umax, float(np.abs(out.u).max()))
        x = plant.step(x, out.u + push)
    return reached, x, umax, held


def test_the_driver_walks_past_a_waypoint_a_push_holds_it_short_of():
    """Through the controller and its leg sequencing: without integral action the robot
    never leaves its first leg (held F_d / K_p = 1.25 m short, each retry's window smaller);
    with it the guard reports held_short and the robot goes on to the last waypoint."""
    reached, x, _, held = _walk(False, 30.0)
    assert reached == [(5.0, 0.0)] and held == 0
    assert abs(x[0] - (5.0 - 28.0 / _riccati_gain()[0, 0])) < 0.05
    reached, x, umax, held = _walk(True)
    assert reached == [(5.0, 0.0), (5.0, 5.0)] and held >= 1
    assert np.linalg.norm(x[:2] - [5.0, 5.0]) < 1.0 and umax <= LIMIT


def test_toward_the_next_waypoint_the_force_starts_from_zero_and_integral_action_stays_armed():
    """Friction holds the robot at every waypoint: waiting a whole horizon at each (as at
    μ = 0.1 with nothing armed past a waypoint: not at the goal in 300 s) is avoided by
    staying armed, so the force grows again as soon as the robot is held. The force itself
    is not carried: a force grown once (noise made a speeding robot look held) would be
    carried from leg to leg with nothing to unwind it (last ten 1.185 on a noisy, delayed,
    white-push mission). A retry toward the same waypoint keeps what it has."""
    held = HeldShort(2, RHO, T, DT, LIMIT)
    held.start_leg(np.array([-5.0, 0.0, 0.0, 0.0]), retry=True)
    for _ in range(21):
        held(np.array([-5.0, 0.0, 0.0, 0.0]))
    assert np.allclose(held.force, [100.0, 0.0])
    held.start_leg(np.array([-4.0, 0.0, 0.0, 0.0]), retry=True)       # retried: kept
    assert held.active and np.allclose(held.force, [100.0, 0.0])
    held.start_leg(np.array([-3.0, -3.0, 0.0, 0.0]), retry=False)     # the next waypoint
    assert held.active and not held.force.any()
    for _ in range(21):                                              # held there: it grows
        held(np.array([-3.0, -3.0, 0.0, 0.0]))
    assert np.allclose(held.force, [100.0 / np.sqrt(2.0)] * 2)   # along ê, per axis
    held.start_leg(np.array([-3.0, -3.0, 1.0, 1.0]), retry=False)     # moving: nothing grows
    for _ in range(21):
        held(np.array([-3.0, -3.0, 1.0, 1.0]))
    assert held.active and not held.force.any()
    held.drop()                                                      # the brake disarms it
    held.start_leg(np.array([0.0, 4.0, 0.0, 0.0]), retry=False)
    for _ in range(21):
        held(np.array([0.0, 4.0, 0.0, 0.0]))
    assert not held.active and not held.force.any()


def _riccati_driver(integral: bool):
    """The driver held at the rover's Riccati gain (no learning, no probing), integral action
    on or off, and the rover it drives."""
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, initial_gain=_riccati_gain(),
                              alpha_a=1e-9, probing_std=0.0, force_limit=LIMIT,
                              integral_action=integral)
    driver = LearningDriver(config, 4, 2, 0, np.random.default_rng(0))
    return driver, ref.Plant(*ref.rover(mass=MASS, stiffness=0.0, damping=DAMPING), DT)


def _against_a_face(face: float, seconds: float = 40.0):
    """The driver (Riccati gain, integral action on) toward (5, 0) with an obstacle's face
    across its way at x = ``face`` (the safety node's nearest: distance, the unit normal
    toward the robot): how often the guard said held_short, the closest approach (m) and
    the largest integral force (N)."""
    driver, plant = _riccati_driver(True)
    x = np.zeros(4)
    driver.set_plan([[5.0, 0.0]], x, 0.0)
    held, closest, biggest = 0, math.inf, 0.0
    for k in range(int(seconds / DT)):
        driver.nearest = (face - x[0], np.array([-1.0, 0.0]))
        out = driver.step(k * DT, x)
        held += 'held_short' in out.policy_event
        biggest = max(biggest, float(np.abs(driver.controller._held_short.force).max()))
        x = plant.step(x, out.u)
        closest = min(closest, face - x[0])
    return held, closest, biggest


def test_a_robot_the_keep_off_holds_off_an_obstacle_is_not_held_short():
    """The waypoint lies 0.5 m past an obstacle's face: the keep-off holds the robot in its
    zone and each leg runs its horizon. That is the safety shell holding it, not a push or
    friction: integral action neither arms nor grows (on, it pushed the robot toward the
    face, and the keep-off pushed the less by it: robot_side's noisy, delayed sinusoid, seed
    3, touched an obstacle 0.3 s after arming so)."""
    held, closest, biggest = _against_a_face(4.5)
    assert held == 0 and biggest == 0.0
    assert closest > 0.0


def _along_a_wall(integral: bool, seconds: float = 40.0):
    """The driver (Riccati gain, integral action on or off) to (3, 0), then on to (8, 0)
    along a wall at y = -0.3 (the nearest obstacle: distance, the unit normal toward the
    robot). Past x = 3.5 a steady push of 40 N back along the way and 15 N into the wall
    holds it, as a field bump pressed robot_side's seed 9 along an obstacle's face. Returns
    the held_short events that armed on a leg the keep-off pushed in, the closest approach
    to the wall (m) and the robot's least distance from (8, 0) (m)."""
    driver, plant = _riccati_driver(integral)
    x = np.zeros(4)
    driver.set_plan([[3.0, 0.0], [8.0, 0.0]], x, 0.0)
    armed, closest, least = 0, math.inf, math.inf
    for k in range(int(seconds / DT)):
        driver.nearest = (x[1] + 0.3, np.array([0.0, 1.0]))
        kept = driver.controller._kept_in_leg
        out = driver.step(k * DT, x)
        armed += kept and 'held_short' in out.policy_event
        push = np.array([-40.0, -15.0]) if x[0] > 3.5 else np.zeros(2)
        x = plant.step(x, out.u + push)
        closest = min(closest, x[1] + 0.3)
        least = min(least, float(np.linalg.norm(x[:2] - [8.0, 0.0])))
    return armed, closest, least


def test_a_robot_pressed_against_a_wall_and_held_short_along_it_gets_there():
    """The keep-off holds the robot off the wall, and the push along the wall holds it short
    of its waypoint (F_d / K_p: ground truth from scipy's Riccati gain). The safety shell
    owns the direction into the wall, not the one along it: integral action arms on the
    legs the keep-off pushed in (they ended elsewhere than the policy's own flight through
    the identified model, keep-off forces included) and grows along the wall, and the robot
    reaches its waypoint without touching. Without integral action it stays short by
    F_d / K_p (robot_side's field bump, seed 9, held 2.4 m short for 320 s so, when a leg
    the keep-off acted in armed nothing)."""
    armed, closest, least = _along_a_wall(True)
    assert armed >= 1 and closest > 0.0 and least < RHO * 1.0
    _, _, least_off = _along_a_wall(False)
    assert least_off > 0.8 * 40.0 / float(_riccati_gain()[0, 0])


def _zero_gain_legs(friction: float, seed: int, seconds: float = 35.0, velocity_std: float = 0.0):
    """The driver from the defaults' zero gain toward a waypoint 5 m off, on the rover with
    Coulomb ``friction`` per axis (N): the held_short events and how often the robot ended
    a leg moving. ``velocity_std``: odometry noise on the velocity the driver reads (m/s,
    per axis; the driver told its variance)."""
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, force_limit=LIMIT)
    driver = LearningDriver(config, 4, 2, 0, np.random.default_rng(seed))
    driver.set_odometry_variance(np.array([0.0, 0.0, velocity_std ** 2, velocity_std ** 2]))
    noise = np.random.default_rng(1000 + seed)
    x = np.zeros(4)
    driver.set_plan([[5.0, 0.0]], x, 0.0)
    held, moving, target = 0, 0, None
    for k in range(int(seconds / DT)):
        read = x + np.concatenate([np.zeros(2), noise.normal(0.0, velocity_std, 2)])
        out = driver.step(k * DT, read)
        held += 'held_short' in out.policy_event
        x = _coulomb_step(x, out.u, friction)
        if target is not None and (k + 1) % int(T / DT) == 0:
            moving += float(np.linalg.norm(x[2:])) > 0.05
        target = out.leg_target
    return held, moving


def test_the_zero_gains_probing_walk_arms_no_integral_action_and_friction_still_does():
    """Before any policy has completed a leg, a leg that ran its horizon arms integral action
    only where the robot ended it at rest: the zero gain's probing walks a frictionless
    robot about (integral action then took over from a learner that had not started: last
    ten 2.35 and 1.78 on two noisy robot-side seeds that fly 1.01 and 1.02 without it),
    while 39 N of friction holds the robot still and arms it."""
    for seed in range(3):
        held, moving = _zero_gain_legs(0.0, seed)
        assert moving >= 1 and held == 0, (seed, held, moving)
    held, _ = _zero_gain_legs(39.0, 0)
    assert held >= 1


def _conveyed_legs(velocity_std: float, seed: int, speed: float = 0.19, seconds: float = 100.0) -> int:
    """The held_short events of the driver from the defaults' zero gain, on a robot carried
    toward a waypoint 100 m off at ``speed`` (m/s) whatever it commands, its velocity read
    with noise σ_v = ``velocity_std``: every leg runs its horizon with the robot moving."""
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, force_limit=LIMIT)
    driver = LearningDriver(config, 4, 2, 0, np.random.default_rng(seed))
    driver.set_odometry_variance(np.array([0.0, 0.0, velocity_std ** 2, velocity_std ** 2]))
    noise = np.random.default_rng(1000 + seed)
    driver.set_plan([[100.0, 0.0]], np.zeros(4), 0.0)
    held = 0
    for k in range(int(seconds / DT)):
        x = np.array([speed * k * DT, 0.0, speed, 0.0])
        read = x + np.concatenate([np.zeros(2), noise.normal(0.0, velocity_std, 2)])
        held += 'held_short' in driver.step(k * DT, read).policy_event
    return held


def test_under_odometry_noise_a_robot_moving_at_its_legs_end_arms_nothing_and_friction_still_does():
    """σ_v = 0.05 m/s: one reading of a robot at rest exceeds 0.15 m/s with probability 1 %
    (the Rayleigh quantile), but one reading of a robot moving at 0.19 m/s falls below it on
    about one step in five: at the end of a leg that ran its horizon it armed integral
    action for a learner that had not started. The mean of the leg's last readings
    (:meth:`Sensing.samples_for`: 10 at this noise) tells moving from at rest: no arming in
    ten legs on any of four seeds (one reading: 2-5 armings per seed), and 39 N of
    friction, which holds the robot still, still arms it."""
    assert [_conveyed_legs(0.05, seed) for seed in range(4)] == [0, 0, 0, 0]
    held, _ = _zero_gain_legs(39.0, 0, velocity_std=0.05)
    assert held >= 1


def test_the_readings_a_mean_needs_bring_the_noise_quantile_to_the_rest_speed():
    """k = (σ_v q / floor)², q the Rayleigh quantile at 1 %: the mean of k readings of a
    robot at rest exceeds the floor with probability at most 1 % (simulated here), and
    exact odometry needs one."""
    sense = Sensing(velocity_std=0.05)
    k = sense.samples_for(0.05)
    assert k == math.ceil((0.05 * math.sqrt(2.0 * math.log(100.0)) / 0.05) ** 2)
    assert sense.rest(0.05, k) == 0.05 and sense.rest(0.05) > 0.15
    rng = np.random.default_rng(0)
    means = rng.normal(0.0, 0.05, (20000, k, 2)).mean(axis=1)
    assert np.mean(np.linalg.norm(means, axis=1) > 0.05) <= 0.01
    assert Sensing().samples_for(0.05) == 1


def _first_leg_then_arming(brake_at: float | None) -> int:
    """The driver on the rover toward a waypoint 5 m off, held by 39 N of Coulomb friction
    that its zero gain's probing does not break, the initial policy marked as one that
    completed a leg (arming then does not wait for the robot to rest), the safety brake put
    on at ``brake_at`` (s; None: never): the held_short events when the first leg has run
    its horizon. The line watch is off."""
    config = ControllerConfig(M=10.0, R=0.02, P_T=0.5, force_limit=LIMIT,
                              divergence_deviation=math.inf)
    driver = LearningDriver(config, 4, 2, 0, np.random.default_rng(0))
    x = np.zeros(4)
    driver.set_plan([[5.0, 0.0]], x, 0.0)
    driver.controller.completed_leg()
    held = 0
    for k in range(int((T + 1.0) / DT)):
        if brake_at is not None and k == round(brake_at / DT):
            driver.controller.revert('a trip of the test', k * DT, brake=True)
        out = driver.step(k * DT, x)
        held += 'held_short' in out.policy_event
        x = _coulomb_step(x, out.u, 39.0)
    return held


def test_a_leg_the_brake_acted_on_arms_no_integral_action():
    """A leg that ran its horizon because the safety brake stopped the robot was held by the
    safety shell, not by a push, like a leg the keep-off acted on: it arms nothing (after a
    brake, 12 of 159 armings on the robot-side rows at 304c4b6, and the rover under white
    0.5 m/s², seed 8, flew its last ten legs at 1.243 of the optimum). The same leg without
    the brake arms it."""
    assert _first_leg_then_arming(None) >= 1
    assert _first_leg_then_arming(2.0) == 0


def _slow_plant_armings(push: float, legs: int = 10, white: float = 0.0) -> tuple[int, int]:
    """The controller on a light, lightly damped rover whose force is dear (24 kg, 8 kg/s,
    R = 2: ``controller_robustness``'s plant 10, whose finite-horizon optimum ends most legs
    short of their window) from the LQ gain as a policy that completed a leg (so that arming
    does not wait for a completed leg), the line watch off, over random legs of 2-8 m, a
    steady ``push`` (N, along x) and a white one (``white``, m/s² per axis) on it:
    (held_short events, legs that ran their horizon)."""
    mass, damping, R = 24.0, 8.0, 2.0
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [np.zeros((2, 2)), -damping / mass * np.eye(2)]])
    B = np.vstack([np.zeros((2, 2)), np.eye(2) / mass])
    plant = ref.Plant(A, B, DT)
    P = solve_continuous_are(A, B, 10.0 * np.eye(4), R * np.eye(2))
    config = ControllerConfig(M=10.0, R=R, P_T=0.5, force_limit=640.0,
                              initial_gain=(B.T @ P / R).tolist(), divergence_deviation=math.inf)
    ctrl = QLearningController(config, 4, 2, 0, np.random.default_rng(3))
    ctrl.start_leg(np.zeros(4), 0.0)
    ctrl.completed_leg()
    rng, noise = np.random.default_rng(4), np.random.default_rng(5)
    t, v, ran_out = 0.0, np.zeros(2), 0
    for _ in range(legs):
        angle, length = rng.uniform(0.0, 2.0 * np.pi), rng.uniform(2.0, 8.0)
        x = np.concatenate([-length * np.array([np.cos(angle), np.sin(angle)]), v])
        ctrl.start_leg(x, t)
        d0 = float(np.linalg.norm(x))
        for k in range(int(round(T / DT))):
            if np.linalg.norm(x) <= config.rho * d0:
                break
            u = np.clip(ctrl.step(t, x), -640.0, 640.0)
            x = plant.step(x, u + np.array([push, 0.0]) + mass * white * noise.standard_normal(2))
            t += DT
        else:
            ran_out += 1
        v = x[2:]
    return ctrl.event_counts[PolicyEvent.HELD_SHORT], ran_out


def test_a_policy_slower_than_its_window_arms_nothing_and_a_push_still_does():
    """A leg that ran its horizon where its own policy, flown through the identified model
    with the probing it applied, would have left the robot too was not held: the policy is
    slow (the finite-horizon optimum of a plant whose force is dear ends its legs short of
    their window), and integral action armed there took ``controller_robustness``'s plant 10
    to 1.07 of the optimum (1.003 without). A steady push holds the robot where the model
    says it would not be, and still arms it."""
    armed, ran_out = _slow_plant_armings(0.0)
    assert ran_out >= 5      # the legs do run out short of their window
    assert armed == 0
    armed, _ = _slow_plant_armings(30.0)
    assert armed >= 1


def test_a_white_push_on_a_slow_plant_seldom_arms_integral_action():
    """On the same slow plant a white push of 0.5 m/s² walks the robot farther from where
    its policy would have taken it than the window over a horizon: apart by more than the
    model's unexplained part explains at 1 % it arms (once in ten legs here); by more than
    the window alone, five times in ten (``controller_robustness``'s plant 37, seven times
    in thirty legs: 1.29 of the Riccati policy against 1.01)."""
    armed, ran_out = _slow_plant_armings(0.0, white=0.5)
    assert ran_out >= 5
    assert armed <= 1
