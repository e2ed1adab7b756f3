"""End to end: `rrtq run` on a plant-only scenario, its recording, its determinism."""

import collections
import json
import os
import pathlib
import subprocess

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

SCENARIO = """
name: e2e
seed: {seed}
bounds: {{x: [-20, 20], y: [-20, 20]}}
start: [-5.0, -5.0]
goal: [10.0, 10.0]
duration: 4.0
perception_radius: 4.0
robot_radius: 0.2
plant: {{model: rover, stiffness: 0.0, force_limit: 150.0}}
disturbance: {{model: gaussian, amplitude: 0.5}}
controller:
  variant: open_loop
  forces: [[0.0, 100.0, 40.0], [2.0, -20.0, 60.0]]
obstacles:
  - {{id: seen, polygon: [[-1, -5], [0, -5], [0, -4], [-1, -4]], appear_at: 1.0}}
  - {{id: known_box, polygon: [[5, 5], [6, 5], [6, 6], [5, 6]], known: true}}
"""

STEP_TOPICS = {'/clock': 'rosgraph_msgs/msg/Clock', '/odom': 'nav_msgs/msg/Odometry',
               '/cmd_force': 'geometry_msgs/msg/WrenchStamped',
               '/controller/state': 'rrtq_msgs/msg/ControllerState',
               '/disturbance': 'rrtq_msgs/msg/Disturbance',
               '/perception/status': 'rrtq_msgs/msg/PerceptionStatus'}


def run(root, tmp, seed, mode, extra=(), executor='events'):
    scenario = tmp / f'e2e_{seed}.yaml'
    scenario.write_text(SCENARIO.format(seed=seed))
    out = tmp / f'run_{seed}_{mode}_{executor}'
    proc = subprocess.run([str(root / 'scripts/rrtq'), 'run', str(scenario), '--out', str(out),
                           '--mode', mode, *extra], capture_output=True, text=True, timeout=180,
                          env={**os.environ, 'RRTQ_EXECUTOR': executor})
    return proc, out


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    root = pathlib.Path(__file__).resolve().parents[1]
    tmp = tmp_path_factory.mktemp('e2e')
    found = {key: run(root, tmp, *key) for key in ((3, 'processes'), (3, 'composed'),
                                                   (4, 'composed'))}
    found[(3, 'composed', 'single')] = run(root, tmp, 3, 'composed', executor='single')
    return found


def odom_bytes(out):
    reader = make_reader(open(out / 'run.mcap', 'rb'))
    return [m.data for _, _, m in reader.iter_messages(topics=['/odom'])]


def test_run_succeeds_and_writes_summary(runs):
    proc, out = runs[(3, 'processes')]
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / 'summary.json').read_text())
    for key in ('success', 'collided', 'time_to_goal_s', 'path_length_m', 'control_effort',
                'min_clearance_m', 'replans', 'replan_ms', 'controller_step_ms',
                'sim_speedup'):
        assert key in summary
    assert summary['success'] is True and summary['collided'] is False
    assert summary['outcome'] == 'duration_elapsed'
    assert summary['steps'] == 81            # t = 0 .. 4 s at 0.05 s
    assert summary['path_length_m'] > 1.0 and summary['control_effort'] > 0.0


def test_lockstep_same_seed_same_odometry_in_both_modes(runs):
    processes, composed = odom_bytes(runs[(3, 'processes')][1]), odom_bytes(runs[(3, 'composed')][1])
    assert len(processes) == 81
    assert processes == composed


def test_lockstep_same_odometry_on_either_executor(runs):
    # rclpy's SingleThreadedExecutor against the EventsExecutor runs use (rrtq_common.executors).
    single = odom_bytes(runs[(3, 'composed', 'single')][1])
    assert len(single) == 81
    assert single == odom_bytes(runs[(3, 'composed')][1])


def test_seed_changes_the_gaussian_disturbance(runs):
    assert odom_bytes(runs[(3, 'composed')][1]) != odom_bytes(runs[(4, 'composed')][1])


def test_every_message_decodes_with_the_right_schema(runs):
    _, out = runs[(3, 'processes')]
    reader = make_reader(open(out / 'run.mcap', 'rb'), decoder_factories=[DecoderFactory()])
    counts = collections.Counter()
    types = {}
    detections = []
    for schema, channel, message, decoded in reader.iter_decoded_messages():
        counts[channel.topic] += 1
        types[channel.topic] = schema.name
        assert channel.message_encoding == 'cdr' and schema.encoding == 'ros2msg'
        if channel.topic == '/odom':
            assert decoded.header.frame_id == 'map' and decoded.child_frame_id == 'base_link'
        if channel.topic == '/perception/status' and decoded.detected:
            detections.append((decoded.header.stamp.sec, list(decoded.detected)))
    for topic, type_name in STEP_TOPICS.items():
        assert types[topic] == type_name
        assert counts[topic] == 81, topic
    assert types['/obstacles/detected'] == 'rrtq_msgs/msg/ObstacleArray'
    assert types['/goal_pose'] == 'geometry_msgs/msg/PoseStamped'
    # known_box at start; 'seen' when it appears inside the perception disc.
    assert counts['/obstacles/detected'] == 2
    # Truth: known_box from the start, 'seen' from t = 1 s.
    assert counts['/obstacles/truth'] == 2
    assert len(detections) == 1 and detections[0][1] == ['seen'] and detections[0][0] >= 1
    summary = reader.get_summary()
    assert summary.statistics.message_count == sum(counts.values())
    assert all(c.compression == 'zstd' for c in summary.chunk_indexes)
    assert all(c.message_index_offsets for c in summary.chunk_indexes)
    assert reader.get_header().profile == 'ros2'


def test_channel_metadata_has_qos_and_type_hash(runs):
    _, out = runs[(3, 'processes')]
    summary = make_reader(open(out / 'run.mcap', 'rb')).get_summary()
    by_topic = {c.topic: c for c in summary.channels.values()}
    for topic in (*STEP_TOPICS, '/obstacles/detected'):
        meta = by_topic[topic].metadata
        assert meta['topic_type_hash'].startswith('RIHS01_') and len(meta['topic_type_hash']) == 71
        offers = yaml.safe_load(meta['offered_qos_profiles'])
        assert len(offers) == 1 and offers[0]['reliability'] == 'reliable'
        assert set(offers[0]) == {'history', 'depth', 'reliability', 'durability', 'deadline',
                                  'lifespan', 'liveliness', 'liveliness_lease_duration',
                                  'avoid_ros_namespace_conventions'}
    latched = yaml.safe_load(by_topic['/obstacles/detected'].metadata['offered_qos_profiles'])
    assert latched[0]['durability'] == 'transient_local'
    assert yaml.safe_load(by_topic['/clock'].metadata['offered_qos_profiles'])[0][
        'durability'] == 'volatile'


def test_schema_text_is_rosbag2_layout(runs):
    """Compare with the definition assembled here from the installed .msg files."""
    from ament_index_python.packages import get_package_share_directory

    def msg(pkg, name):
        with open(f'{get_package_share_directory(pkg)}/msg/{name}.msg') as f:
            return f.read()

    sep = '\n' + '=' * 80 + '\n'
    # PoseStamped -> Header (-> Time), Pose (-> Point, Quaternion): sorted, depth first.
    expected = (msg('geometry_msgs', 'PoseStamped')
                + sep + 'MSG: geometry_msgs/Pose\n' + msg('geometry_msgs', 'Pose')
                + sep + 'MSG: geometry_msgs/Point\n' + msg('geometry_msgs', 'Point')
                + sep + 'MSG: geometry_msgs/Quaternion\n' + msg('geometry_msgs', 'Quaternion')
                + sep + 'MSG: std_msgs/Header\n' + msg('std_msgs', 'Header')
                + sep + 'MSG: builtin_interfaces/Time\n' + msg('builtin_interfaces', 'Time'))
    _, out = runs[(3, 'processes')]
    summary = make_reader(open(out / 'run.mcap', 'rb')).get_summary()
    schemas = {s.name: s.data.decode() for s in summary.schemas.values()}
    assert schemas['geometry_msgs/msg/PoseStamped'] == expected
    array = schemas['rrtq_msgs/msg/ObstacleArray']
    assert array.startswith(msg('rrtq_msgs', 'ObstacleArray'))
    assert array.count('MSG: ') == len(set(array.split('MSG: ')[1:]))   # each dependency once
    assert 'MSG: rrtq_msgs/Obstacle\n' in array and 'MSG: geometry_msgs/Point32\n' in array


def test_paced_mode_follows_the_wall_clock(tmp_path):
    root = pathlib.Path(__file__).resolve().parents[1]
    proc, out = run(root, tmp_path, 5, 'composed', extra=('--speed', '4.0'))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['speed'] == 4.0 and summary['steps'] == 81
    # Paced at 4x: never faster than the pace (slower only if the machine cannot keep up).
    assert summary['sim_speedup'] <= 4.4


def test_report_from_the_recording_agrees_with_the_live_summary(runs, tmp_path):
    from rrtq_bringup.report.run import report
    _, out = runs[(3, 'processes')]
    live = json.loads((out / 'summary.json').read_text())
    offline = report(out / 'run.mcap', tmp_path / 'report')
    assert offline['steps'] == live['steps']
    assert offline['path_length_m'] == pytest.approx(live['path_length_m'], rel=1e-12)
    assert offline['min_clearance_m'] == pytest.approx(live['min_clearance_m'], rel=1e-9)
    assert offline['control_effort'] == pytest.approx(live['control_effort'], rel=1e-9)
    assert offline['collided'] is False
    for name in ('map.png', 'timeseries.png'):
        assert (tmp_path / 'report' / name).stat().st_size > 10_000
