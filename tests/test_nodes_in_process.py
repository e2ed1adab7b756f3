"""The simulator-side nodes on an in-process executor, driven by the test."""

import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rrtq_msgs.msg import ControllerState, Disturbance, ObstacleArray
from scipy.integrate import solve_ivp

from rrtq_bringup.recorder_node import RecorderNode
from rrtq_bringup.testing import Collector, spin_until, wait_for_messages
from rrtq_common import conversions as conv
from rrtq_common import qos
from rrtq_sim.disturbance_node import DisturbanceNode
from rrtq_sim.simulator_node import SimulatorNode
from rrtq_sim.spawner_node import SpawnerNode

M, K, C = 40.0, 20.0, 45.0
A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [-K / M, 0, -C / M, 0], [0, -K / M, 0, -C / M]])
B = np.array([[0, 0], [0, 0], [1 / M, 0], [0, 1 / M]])
F = np.array([[0.0], [0.0], [-1.0], [1.0]])


def params(**kw):
    return [Parameter(k, value=v) for k, v in kw.items()]


def test_simulator_lockstep_matches_the_continuous_plant(ros):
    context, executor, _ = ros
    sim = SimulatorNode(context=context, parameter_overrides=params(
        A=A.ravel().tolist(), B=B.ravel().tolist(), F=F.ravel().tolist(), dt=0.05,
        start=[1.0, -2.0], spring_anchor='world_origin', acks=['cmd_force'],
        wait_for=['/odom:1']))
    driver = __import__('rclpy').create_node('driver', context=context)
    executor.add_node(sim)
    executor.add_node(driver)
    force = (30.0, -12.0)
    cmd_pub = driver.create_publisher(WrenchStamped, '/cmd_force', qos.STREAM)
    odoms: list[Odometry] = []
    hold = {'on': False}

    def answer(msg):
        odoms.append(msg)
        if hold['on']:
            return
        cmd = WrenchStamped()
        cmd.header.stamp = msg.header.stamp
        cmd.wrench.force.x, cmd.wrench.force.y = force
        cmd_pub.publish(cmd)
    driver.create_subscription(Odometry, '/odom', answer, qos.STREAM)
    assert spin_until(executor, lambda: len(odoms) >= 21, 20.0)
    hold['on'] = True
    count = len(odoms)
    spin_until(executor, lambda: False, 0.5)
    # Lock-step: without the acknowledgement of the last step, no step is taken.
    assert len(odoms) == count + 1 or len(odoms) == count
    stamps = [conv.stamp_ns(m.header.stamp) for m in odoms[:21]]
    assert stamps == [k * 50_000_000 for k in range(21)]
    sol = solve_ivp(lambda t, x: A @ x + B @ np.array(force), (0.0, 1.0),
                    [1.0, -2.0, 0.0, 0.0], rtol=1e-11, atol=1e-12)
    assert np.allclose(conv.odometry_state(odoms[20]), sol.y[:, -1], atol=1e-8)


def test_simulator_measures_the_truth_with_noise_and_delays_the_force(ros):
    """/odom/truth is the continuous plant under the force commanded 3 steps (0.15 s) before,
    zero until then; /odom is that truth measured by the run seed's noise generator (the
    same draws, step by step) with its variances in the covariances."""
    from rrtq_sim.odometry import OdometryNoise, OdometryNoiseConfig, odometry_rng
    context, executor, _ = ros
    sigma_p, sigma_v, seed = 0.02, 0.1, 11
    sim = SimulatorNode(context=context, parameter_overrides=params(
        A=A.ravel().tolist(), B=B.ravel().tolist(), F=F.ravel().tolist(), dt=0.05, seed=seed,
        start=[1.0, -2.0], spring_anchor='world_origin', acks=['cmd_force'],
        wait_for=['/odom:1', '/odom/truth:1'], actuation_delay=0.15, position_std=sigma_p,
        velocity_std=sigma_v))
    driver = __import__('rclpy').create_node('driver', context=context)
    executor.add_node(sim)
    executor.add_node(driver)
    force = (30.0, -12.0)
    cmd_pub = driver.create_publisher(WrenchStamped, '/cmd_force', qos.STREAM)
    truth = Collector(driver, Odometry, '/odom/truth', qos.STREAM)
    measured: list[Odometry] = []

    def answer(msg):
        measured.append(msg)
        cmd = WrenchStamped()
        cmd.header.stamp = msg.header.stamp
        cmd.wrench.force.x, cmd.wrench.force.y = force
        cmd_pub.publish(cmd)
    driver.create_subscription(Odometry, '/odom', answer, qos.STREAM)
    assert spin_until(executor, lambda: len(measured) >= 21 and len(truth) >= 21, 20.0)
    stamps = [conv.stamp_ns(m.header.stamp) for m in truth.messages[:21]]
    assert stamps == [conv.stamp_ns(m.header.stamp) for m in measured[:21]]
    assert stamps == [k * 50_000_000 for k in range(21)]
    x0 = [1.0, -2.0, 0.0, 0.0]
    true_x = [conv.odometry_state(m) for m in truth.messages[:21]]
    free = solve_ivp(lambda t, x: A @ x, (0.0, 0.15), x0, rtol=1e-11, atol=1e-12,
                     dense_output=True)
    for k in range(4):                   # the spring alone until the first force acts
        assert np.allclose(true_x[k], free.sol(0.05 * k), atol=1e-8)
    pushed = solve_ivp(lambda t, x: A @ x + B @ np.array(force), (0.15, 1.0), free.sol(0.15),
                       rtol=1e-11, atol=1e-12)
    assert np.allclose(true_x[20], pushed.y[:, -1], atol=1e-8)
    noise = OdometryNoise(OdometryNoiseConfig(position_std=sigma_p, velocity_std=sigma_v),
                          odometry_rng(seed))
    for t_msg, m_msg in zip(truth.messages[:21], measured[:21]):
        assert np.array_equal(conv.odometry_state(m_msg),
                              noise.measure(conv.odometry_state(t_msg)))
        assert (m_msg.header.frame_id, m_msg.child_frame_id) == ('map', 'base_link')
        cov_p, cov_v = np.reshape(m_msg.pose.covariance, (6, 6)), np.reshape(
            m_msg.twist.covariance, (6, 6))
        assert np.array_equal(cov_p, np.diag([sigma_p ** 2] * 2 + [0.0] * 4))
        assert np.array_equal(cov_v, np.diag([sigma_v ** 2] * 2 + [0.0] * 4))
        assert not np.any(t_msg.pose.covariance) and not np.any(t_msg.twist.covariance)
    assert not np.array_equal(conv.odometry_state(measured[5]), true_x[5])


def test_simulator_rejects_non_finite_force(ros):
    context, executor, _ = ros
    sim = SimulatorNode(context=context, parameter_overrides=params(
        A=A.ravel().tolist(), B=B.ravel().tolist(), F=F.ravel().tolist(), start=[0.0, 0.0],
        acks=['cmd_force'], wait_for=['/odom:1']))
    driver = __import__('rclpy').create_node('driver', context=context)
    executor.add_node(sim)
    executor.add_node(driver)
    cmd_pub = driver.create_publisher(WrenchStamped, '/cmd_force', qos.STREAM)
    odoms = []

    def answer(msg):
        odoms.append(msg)
        cmd = WrenchStamped()
        cmd.header.stamp = msg.header.stamp
        cmd.wrench.force.x = float('nan')
        cmd_pub.publish(cmd)
    driver.create_subscription(Odometry, '/odom', answer, qos.STREAM)
    assert spin_until(executor, lambda: len(odoms) >= 5, 20.0)
    assert np.all(conv.odometry_state(odoms[4]) == 0.0)      # held at rest, no NaN
    assert sim.rejected_inputs >= 4


def test_spawner_perceives_along_a_scripted_path(ros, tmp_path):
    context, executor, _ = ros
    scenario = tmp_path / 's.yaml'
    scenario.write_text("""
bounds: {x: [-50, 50], y: [-50, 50]}
start: [0.0, 0.0]
goal: [40.0, 0.0]
perception_radius: 3.0
controller: {variant: open_loop, forces: [[0.0, 0.0, 0.0]]}
obstacles:
  - {id: ahead, polygon: [[10, 1], [11, 1], [11, 2], [10, 2]]}
  - {id: mapped_but_gone, polygon: [[20, -2], [21, -2], [21, -1], [20, -1]], known: true, vanish_at: 0.0}
  - {id: late, polygon: [[30, 1], [31, 1], [31, 2], [30, 2]], appear_at: 29.0}
  - {id: far, polygon: [[20, 30], [21, 30], [21, 31], [20, 31]]}
  - {id: map, polygon: [[-40, -40], [-39, -40], [-39, -39], [-40, -39]], known: true}
""")
    spawner = SpawnerNode(context=context, parameter_overrides=params(scenario=str(scenario)))
    driver = __import__('rclpy').create_node('driver', context=context)
    executor.add_node(spawner)
    executor.add_node(driver)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    detected = Collector(driver, ObstacleArray, '/obstacles/detected', latched)
    # The spawner stands on the simulator's side: it perceives from the true odometry.
    odom_pub = driver.create_publisher(Odometry, '/odom/truth', qos.STREAM)
    wait_for_messages(executor, detected, 1)
    assert spin_until(executor, lambda: spawner.count_subscribers('/odom/truth') and
                      driver.count_subscribers('/odom/truth') >= 1, 10.0)
    # The robot moves along y = 0 at 1 m/s, one odometry message per second.
    for t in range(0, 41):
        odom_pub.publish(conv.odometry_msg(t * 10**9, np.array([float(t), 0.0, 1.0, 0.0])))
    spin_until(executor, lambda: False, 1.0)
    sets = [(round(conv.stamp_ns(m.header.stamp) * 1e-9), sorted(o.id for o in m.obstacles))
            for m in detected.messages]
    assert sets == [
        (0, ['map', 'mapped_but_gone']),
        (8, ['ahead', 'map', 'mapped_but_gone']),          # within 3 m of (10..11, 1..2)
        (18, ['ahead', 'map']),                            # location seen empty
        (29, ['ahead', 'late', 'map']),                    # appears while in range
    ]


def test_worst_case_disturbance_is_the_game_saddle_point(ros):
    context, executor, _ = ros
    gamma, T = 3.0, 10.0
    Mw, Rw, PT = np.eye(4), 0.1 * np.eye(2), 0.5 * np.eye(4)
    node = DisturbanceNode(context=context, parameter_overrides=params(
        model='worst_case', F=F.ravel().tolist(), amplitude=100.0, gamma=gamma,
        A=A.ravel().tolist(), B=B.ravel().tolist(), M=Mw.ravel().tolist(),
        R=Rw.ravel().tolist(), P_T=PT.ravel().tolist(), horizon=T))
    driver = __import__('rclpy').create_node('driver', context=context)
    executor.add_node(node)
    executor.add_node(driver)
    out = Collector(driver, Disturbance, '/disturbance', qos.STREAM)
    # The worst case plays against the true state (/odom/truth), not the measurement.
    odom_pub = driver.create_publisher(Odometry, '/odom/truth', qos.STREAM)
    state_pub = driver.create_publisher(ControllerState, '/controller/state', qos.STREAM)
    assert spin_until(executor, lambda: node.count_publishers('/odom/truth') and
                      node.count_publishers('/controller/state'), 10.0)
    x = np.array([3.0, -1.0, 0.5, 0.2])
    target = np.array([1.0, 1.0])
    tau = 6.5
    state = ControllerState(time_to_go=tau)
    state.leg_target.x, state.leg_target.y = target
    state.header.stamp = conv.time_msg(2 * 10**9)
    state_pub.publish(state)                 # the join must wait for both, in any order
    odom_pub.publish(conv.odometry_msg(2 * 10**9, x))
    wait_for_messages(executor, out, 1)
    # Independent game Riccati: dP/dtau = A'P + PA + M - P B R^-1 B' P + g^-2 P F F' P.
    def rhs(_, p):
        P = p.reshape(4, 4)
        return (A.T @ P + P @ A + Mw - P @ B @ np.linalg.solve(Rw, B.T) @ P
                + P @ F @ F.T @ P / gamma**2).ravel()
    P = solve_ivp(rhs, (0.0, tau), PT.ravel(), rtol=1e-11, atol=1e-12).y[:, -1].reshape(4, 4)
    xbar = x - np.array([*target, 0.0, 0.0])
    expected = F.T @ P @ xbar / gamma**2
    assert np.allclose(out.messages[0].value, expected, rtol=1e-6, atol=1e-9)
    assert out.messages[0].model == 'worst_case'


def recorder_and_odometry(context, executor, tmp_path, before=lambda talker: None):
    """(an /odom publisher, a recorder to ``tmp_path/r.mcap`` that has subscribed to it)."""
    talker = __import__('rclpy').create_node('talker', context=context)
    executor.add_node(talker)
    talker.kept = before(talker)                     # published before the recorder starts
    stream = talker.create_publisher(Odometry, '/odom', qos.STREAM)
    recorder = RecorderNode(context=context, parameter_overrides=params(
        output=str(tmp_path / 'r.mcap')))
    executor.add_node(recorder)
    assert spin_until(executor, lambda: recorder.recorder.has_topic('/odom') and
                      stream.get_subscription_count() >= 1, 10.0)
    return stream, recorder


def test_recorder_gets_latched_messages_published_before_it_started(ros, tmp_path):
    context, executor, _ = ros
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    def latch(talker):
        latched = talker.create_publisher(ObstacleArray, '/obstacles/detected', qos.LATCHED)
        latched.publish(conv.obstacle_array_msg(7, [('a', np.array([[0, 0], [1, 0], [1, 1.0]]))]))
        return latched
    stream, recorder = recorder_and_odometry(context, executor, tmp_path, before=latch)
    for k in range(50):
        stream.publish(conv.odometry_msg(k, np.array([k, 0.0, 0.0, 0.0])))
    assert spin_until(executor, lambda: recorder.recorder.message_count >= 51, 10.0)
    executor.remove_node(recorder)
    recorder.destroy_node()
    reader = make_reader(open(tmp_path / 'r.mcap', 'rb'), decoder_factories=[DecoderFactory()])
    got = {}
    for _, channel, _, decoded in reader.iter_decoded_messages():
        got.setdefault(channel.topic, []).append(decoded)
    assert [o.id for o in got['/obstacles/detected'][0].obstacles] == ['a']
    assert [m.pose.pose.position.x for m in got['/odom']] == [float(k) for k in range(50)]


def learning_controller(context, **extra):
    from rrtq_controller.controller_node import ControllerNode
    return ControllerNode(context=context, parameter_overrides=params(
        variant='nominal', M=[10.0], R=[0.02], initial_gain=[40.0, 0.0, 30.0, 0.0, 0.0, 40.0, 0.0, 30.0],
        probing_std=5.0, **extra))


def drive_with_plan(context, executor, node):
    """A driver node that latches a one-waypoint plan to (3, 0); (commands, odometry pub)."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path
    driver = __import__('rclpy').create_node('driver', context=context)
    executor.add_node(node)
    executor.add_node(driver)
    cmds = Collector(driver, WrenchStamped, '/cmd_force', qos.STREAM)
    odom_pub = driver.create_publisher(Odometry, '/odom', qos.STREAM)
    plan_pub = driver.create_publisher(Path, '/plan', qos.LATCHED)
    plan = Path()
    plan.poses = [PoseStamped()]
    plan.poses[0].pose.position.x = 3.0
    plan_pub.publish(plan)
    return cmds, odom_pub


def test_controller_rejects_non_finite_odometry_without_learning_from_it(ros):
    context, executor, _ = ros
    node = learning_controller(context)
    cmds, odom_pub = drive_with_plan(context, executor, node)
    assert spin_until(executor, lambda: node.count_publishers('/odom') >= 1, 10.0)
    for k in range(5):
        odom_pub.publish(conv.odometry_msg(k * 50_000_000, np.zeros(4)))
    wait_for_messages(executor, cmds, 5)
    weights = node.driver.controller.critic_weights.copy()
    odom_pub.publish(conv.odometry_msg(5 * 50_000_000, np.array([np.nan, 0.0, 0.0, 0.0])))
    wait_for_messages(executor, cmds, 6)
    last = cmds.messages[-1].wrench.force
    assert (last.x, last.y) == (0.0, 0.0)
    assert np.array_equal(node.driver.controller.critic_weights, weights)
    assert np.all(np.isfinite(node.driver.controller.actor_weights))


def test_controller_commands_zero_when_odometry_goes_stale(ros):
    context, executor, _ = ros
    node = learning_controller(context, stale_timeout_s=0.3, probing_decay=1.0)
    cmds, odom_pub = drive_with_plan(context, executor, node)
    assert spin_until(executor, lambda: node.count_publishers('/odom') >= 1
                      and 'plan' in node.gate.latest, 10.0)
    odom_pub.publish(conv.odometry_msg(0, np.zeros(4)))
    wait_for_messages(executor, cmds, 1)
    assert abs(cmds.messages[0].wrench.force.x) > 1.0      # pushing toward x = 3
    spin_until(executor, lambda: False, 1.0)                # no odometry for 1 s
    assert len(cmds) >= 3
    assert all((m.wrench.force.x, m.wrench.force.y) == (0.0, 0.0) for m in cmds.messages[1:])


@pytest.mark.parametrize('reported', ['nearest', 'ahead'])
def test_controller_keeps_off_the_obstacle_the_safety_status_reports(ros, reported):
    """The wiring of the keep-off: the robot moves toward its waypoint (3, 0) at 0.5 m/s,
    the policy pushes it on; a /safety/status with a detected obstacle 0.1 m ahead (its
    direction to the robot -x), reported as the nearest or, with the nearest 10 m off to
    the side, as the one ahead along the velocity, turns the command back, and
    ControllerState.keep_off says by how much."""
    from geometry_msgs.msg import Vector3
    from rrtq_msgs.msg import SafetyStatus
    context, executor, _ = ros
    node = learning_controller(context)
    cmds, odom_pub = drive_with_plan(context, executor, node)
    driver = [n for n in executor.get_nodes() if n.get_name() == 'driver'][0]
    states = Collector(driver, ControllerState, '/controller/state', qos.STREAM)
    safety_pub = driver.create_publisher(SafetyStatus, '/safety/status', qos.STREAM)
    assert spin_until(executor, lambda: node.count_publishers('/odom') >= 1
                      and 'plan' in node.gate.latest, 10.0)
    moving = np.array([0.0, 0.0, 0.5, 0.0])
    odom_pub.publish(conv.odometry_msg(0, moving))
    wait_for_messages(executor, cmds, 1)
    assert cmds.messages[0].wrench.force.x > 1.0                 # toward x = 3
    facing, aside = (0.1, Vector3(x=-1.0, y=0.0)), (10.0, Vector3(x=0.0, y=1.0))
    near, ahead = (facing, (float('inf'), Vector3())) if reported == 'nearest' else (aside, facing)
    safety_pub.publish(SafetyStatus(obstacle_distance=near[0], obstacle_direction=near[1],
                                    ahead_distance=ahead[0], ahead_direction=ahead[1]))
    assert spin_until(executor, lambda: 'safety' in node.gate.latest, 10.0)
    odom_pub.publish(conv.odometry_msg(50_000_000, moving))
    wait_for_messages(executor, cmds, 2)
    wait_for_messages(executor, states, 2)
    assert cmds.messages[1].wrench.force.x < 0.0                 # pushed back, away from it
    assert states.messages[1].keep_off > 0.0


def test_recorder_writes_what_is_queued_when_the_run_ends(ros, tmp_path):
    # `rrtq robot` ends on a busy machine with the recorder behind: what reached its queue
    # but was never taken (the last odometry, the controller's last state) is written when
    # the node is destroyed, after the context is shut down as SIGINT does.
    context, executor, _ = ros
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    stream, recorder = recorder_and_odometry(context, executor, tmp_path)
    executor.remove_node(recorder)                     # the recorder falls behind: no spin
    for k in range(200):
        stream.publish(conv.odometry_msg(k, np.array([k, 0.0, 0.0, 0.0])))
    spin_until(executor, lambda: False, 0.5)           # delivery, no take
    assert recorder.recorder.message_count == 0
    context.try_shutdown()
    recorder.destroy_node()
    reader = make_reader(open(tmp_path / 'r.mcap', 'rb'), decoder_factories=[DecoderFactory()])
    xs = [m.pose.pose.position.x for _, c, _, m in reader.iter_decoded_messages()
          if c.topic == '/odom']
    assert xs == [float(k) for k in range(200)]
