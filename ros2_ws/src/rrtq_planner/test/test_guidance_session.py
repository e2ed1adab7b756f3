"""GuidanceSession: the planner's waypoints and augmented set in, the controller's reference out.

Judged on geometry that does not come from the code: the reference starts at the robot,
keeps off the obstacle's repulsive boundary, respects v²κ <= a_max and |v| <= v_max, holds
still without a path, and is rebuilt exactly when the plan or the obstacles change.
"""

import numpy as np

from rrtq_common.geometry import polygon_from_circle
from rrtq_common.lockstep import OnChange
from rrtq_common.polygon_set import PolygonSet
from rrtq_planner.guidance import GuidanceConfig, GuidanceSession, ReferenceStatus

CONFIG = GuidanceConfig(mode='gvf', v_max=2.0, a_max=2.0, horizon=5.0, dt=0.05)
DISC = polygon_from_circle((5.0, 0.0), 1.0, 24)


def obstacles(stamp, *polys):
    return OnChange(stamp, lambda: [(f'o{i}', p) for i, p in enumerate(polys)])


def test_no_path_holds_the_robot_at_rest():
    session = GuidanceSession(CONFIG)
    out = session.cycle(3.0, [1.0, 2.0, 0.5, 0.0], np.zeros((0, 2)), 0, None)
    assert out.status is ReferenceStatus.NO_PATH
    assert len(out.reference.t) == 101 and np.allclose(out.reference.t, 3.0 + 0.05 * np.arange(101))
    assert np.allclose(out.reference.positions, [1.0, 2.0])
    assert np.allclose(out.reference.velocities, 0.0)


def lateral_acceleration(points, dt):
    """v² κ at interior samples: circumradius of three samples, speed of the chord."""
    a = np.linalg.norm(points[1:-1] - points[:-2], axis=1)
    b = np.linalg.norm(points[2:] - points[1:-1], axis=1)
    c = np.linalg.norm(points[2:] - points[:-2], axis=1)
    u, w = points[1:-1] - points[:-2], points[2:] - points[1:-1]
    cross = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
    with np.errstate(divide='ignore', invalid='ignore'):
        kappa = np.where(a * b * c > 0, 2.0 * cross / (a * b * c), 0.0)
    return (c / (2.0 * dt)) ** 2 * kappa


def test_reference_bends_round_the_obstacle_within_the_limits():
    session = GuidanceSession(CONFIG)
    waypoints = np.array([[10.0, 0.0]])          # straight through the disc
    state = np.array([0.0, 0.0, 0.0, 0.0])
    stamp = 50_000_000
    out = session.cycle(0.0, state, waypoints, stamp, obstacles(7, DISC))
    assert out.obstacles_stamp_ns == 7 and out.plan_stamp_ns == stamp
    # One reference (5 s: past the disc): the speed profile's bound, sampled in time.
    first = lateral_acceleration(out.reference.positions, CONFIG.dt)
    assert np.mean(first <= CONFIG.a_max) >= 0.95 and first.max() <= 1.15 * CONFIG.a_max
    positions, velocities = [], []
    # Drive a perfect tracker along the reference and collect what it was told.
    for k in range(200):
        ref = out.reference
        assert np.hypot(*(ref.positions[0] - state[:2])) < 0.3
        positions.append(ref.positions[1])
        velocities.append(ref.velocities[1])
        state = np.r_[ref.positions[1], ref.velocities[1]]
        out = session.cycle((k + 1) * 0.05, state, waypoints, stamp, obstacles(7, DISC))
    pts, vel = np.array(positions), np.array(velocities)
    assert np.hypot(*(pts[-1] - [10.0, 0.0])) < 0.5            # at the goal within 10 s
    clearance = np.array([PolygonSet([DISC]).nearest(p)[0] for p in pts])
    assert clearance.min() > CONFIG.repulsive_offset
    speed = np.hypot(vel[:, 0], vel[:, 1])
    assert speed.max() <= CONFIG.v_max + 1e-9
    # Cut afresh every step from the tracker's state, the driven samples stay close to it.
    assert np.mean(lateral_acceleration(pts, CONFIG.dt) <= 1.1 * CONFIG.a_max) >= 0.9
    assert session.rollouts == 1                                 # never rebuilt or re-rolled


def test_track_is_kept_while_passed_waypoints_drop_and_rebuilt_on_changes():
    session = GuidanceSession(CONFIG)
    state = np.zeros(4)
    plan = np.array([[3.0, 0.0], [6.0, 3.0], [9.0, 3.0]])
    session.cycle(0.0, state, plan, 1, obstacles(1))
    track = session.track
    session.cycle(0.05, state, plan[1:], 2, obstacles(1))        # the robot passed (3, 0)
    assert session.track is track
    session.cycle(0.1, state, np.array([[6.0, 2.0], [9.0, 3.0]]), 3, obstacles(1))
    assert session.track is not track                            # a different path
    track = session.track
    session.cycle(0.15, state, np.array([[6.0, 2.0], [9.0, 3.0]]), 3, obstacles(4, DISC))
    assert session.track is not track                            # a new obstacle set
    out = session.cycle(0.2, state, np.zeros((0, 2)), 5, obstacles(4, DISC))
    assert session.track is None and out.status is ReferenceStatus.NO_PATH
    assert out.rollout == 3


def test_a_rebuilt_track_continues_the_robots_motion():
    # The robot flies north at 2 m/s when a new plan sends it east: the new curve must
    # leave along its velocity and turn within v²κ <= a_max at the robot's speed.
    state = np.array([0.0, 0.0, 0.0, 2.0])
    session = GuidanceSession(CONFIG)
    out = session.cycle(0.0, state, np.array([[20.0, 0.0]]), 1, obstacles(1))
    ref = out.reference
    assert np.allclose(ref.velocities[0], state[2:], atol=1e-9)   # heading and speed kept
    lateral = lateral_acceleration(ref.positions, CONFIG.dt)
    moving = np.hypot(*ref.velocities[1:-1].T) > 0.1
    assert lateral[moving].max() <= 1.05 * CONFIG.a_max
    # The turn the robot can fly at 2 m/s (radius v²/a_max = 2 m) takes it that far north.
    assert ref.positions[:, 1].max() >= 0.8 * state[3] ** 2 / CONFIG.a_max
    # Then it is back on the path, heading east at v_max.
    assert abs(ref.positions[-1, 1]) < 0.3 and ref.velocities[-1, 0] > 0.9 * CONFIG.v_max
    # A robot at rest turns at once, as before.
    rest = GuidanceSession(CONFIG).cycle(0.0, np.zeros(4), np.array([[20.0, 0.0]]), 1,
                                         obstacles(1)).reference
    assert np.abs(rest.positions[:, 1]).max() < 1e-9


def test_the_connector_yields_to_an_obstacle_ahead():
    # Heading at 2 m/s for a disc 1.2 m ahead while the path goes east: the connector's
    # turn (radius v²/(0.8 a_max) = 2.5 m about (2.5, 0)) would cut 0.17 m into the disc;
    # the field takes over near the obstacle and the curve keeps off its Q boundary.
    disc = polygon_from_circle((0.0, 2.2), 1.0, 24)
    state = np.array([0.0, 0.0, 0.0, 2.0])
    session = GuidanceSession(CONFIG)
    session.cycle(0.0, state, np.array([[20.0, 0.0]]), 1, obstacles(2, disc))
    curve = session.track.curve
    clearance = np.array([PolygonSet([disc]).nearest(p)[0] for p in curve.points])
    assert clearance.min() > CONFIG.repulsive_offset
