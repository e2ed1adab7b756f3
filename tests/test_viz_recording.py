"""A recording Foxglove's 3D panel draws: /tf, obstacle markers, the layout, the video.

Everything is read back with mcap_ros2's decoder (the schema text in the file, not the
workspace's message classes) and judged against the scenario's own times and shapes and
against the recorded obstacle sets themselves.
"""

import json
import pathlib
import subprocess

import numpy as np
import pytest
import shapely
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image

ROOT = pathlib.Path(__file__).resolve().parents[1]

SCENARIO = """
name: viz
seed: 3
bounds: {x: [-10, 10], y: [-10, 10]}
start: [-6.0, -6.0]
goal: [6.0, 5.0]
duration: 3.0
perception_radius: 5.0
robot_radius: 0.3
plant: {model: rover, stiffness: 0.0}
controller:
  variant: nominal
  M: 10.0
  R: 0.02
  initial_gain: [[40, 0, 30, 0], [0, 40, 0, 30]]
planner: {steer_distance: 3.0, iterations_per_step: 20, max_nodes: 400}
obstacles:
  - {id: box, polygon: [[-4, -7], [-3, -7], [-3, -6], [-4, -6]], known: true}
  - {id: late, polygon: [[-6, -3], [-5, -3], [-5, -2], [-6, -2]], appear_at: 1.0}
  - {id: gone, polygon: [[-8, -4], [-7, -4], [-7, -3], [-8, -3]], known: true, vanish_at: 1.5}
  - {id: ell, polygon: [[-9, -9], [-7, -9], [-7, -8.5], [-8.5, -8.5], [-8.5, -7], [-9, -7]],
     known: true}
"""
APPEAR, VANISH = 1.0, 1.5
ELL = [(-9, -9), (-7, -9), (-7, -8.5), (-8.5, -8.5), (-8.5, -7), (-9, -7)]
LAYERS = {'/viz/obstacles/truth': ('truth', '/obstacles/truth'),
          '/viz/obstacles/detected': ('detected', '/obstacles/detected'),
          '/viz/obstacles/augmented': ('augmented', '/obstacles/augmented')}
ADD, DELETE = 0, 2


def stamp(header):
    return header.stamp.sec + header.stamp.nanosec * 1e-9


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('viz')
    scenario = tmp / 'viz.yaml'
    scenario.write_text(SCENARIO)
    out = tmp / 'run'
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(scenario), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=300)
    assert (out / 'run.mcap').exists(), proc.stderr
    return out / 'run.mcap'


@pytest.fixture(scope='module')
def decoded(recording):
    """topic -> [(schema name, message)] in log-time order, decoded independently."""
    factory = DecoderFactory()
    out: dict[str, list] = {}
    with open(recording, 'rb') as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.topic == '/rosout':
                continue
            decode = factory.decoder_for(channel.message_encoding, schema)
            out.setdefault(channel.topic, []).append((schema.name, decode(message.data)))
    return out


def replay(messages):
    """Marker state after each MarkerArray: [(stamp, {id: marker})], ADD and DELETE applied."""
    shown: dict[int, object] = {}
    states = []
    for _, array in messages:
        for marker in array.markers:
            if marker.action == ADD:
                shown[marker.id] = marker
            elif marker.action == DELETE:
                assert marker.id in shown, 'DELETE of a marker never added'
                del shown[marker.id]
        states.append((stamp(array.markers[0].header) if array.markers else None,
                       dict(shown)))
    return states


def test_every_obstacle_set_has_its_markers_with_deletes(decoded):
    for topic, (ns, source) in LAYERS.items():
        schemas = {name for name, _ in decoded[topic]}
        assert schemas == {'visualization_msgs/msg/MarkerArray'}
        sets = [(stamp(m.header), sorted(o.id for o in m.obstacles)) for _, m in decoded[source]]
        states = replay(decoded[topic])
        assert len(states) == len(sets)
        for (t_set, ids), (t_markers, shown) in zip(sets, states):
            assert t_markers in (t_set, None) and (t_markers is not None or not ids)
            assert sorted(m.text for m in shown.values()) == ids
            assert {m.ns for m in shown.values()} <= {ns}
            assert all(m.header.frame_id == 'map' for m in shown.values())


def test_true_obstacles_exist_in_the_markers_exactly_when_the_scenario_says(decoded):
    states = replay(decoded['/viz/obstacles/truth'])
    for t, shown in states:
        names = {m.text for m in shown.values()}
        assert ('late' in names) == (t >= APPEAR - 1e-9)
        assert ('gone' in names) == (t < VANISH - 1e-9)
        assert {'box', 'ell'} <= names
    deletes = [(stamp(m.header), m.ns) for _, a in decoded['/viz/obstacles/truth']
               for m in a.markers if m.action == DELETE]
    assert deletes == [(VANISH, 'truth')]
    # The robot sees 'gone' is no longer there (it is within the perception disc): its
    # detected marker is deleted too, at the same step.
    detected_deletes = [stamp(m.header) for _, a in decoded['/viz/obstacles/detected']
                        for m in a.markers if m.action == DELETE]
    assert detected_deletes == [VANISH]


def test_namespaces_and_colours_are_distinct_and_the_fill_is_exact(decoded):
    colours = {}
    for topic, (ns, _) in LAYERS.items():
        added = [m for _, a in decoded[topic] for m in a.markers if m.action == ADD]
        assert {m.ns for m in added} == {ns}
        assert len({(m.color.r, m.color.g, m.color.b, m.color.a) for m in added}) == 1
        colours[ns] = (added[0].color.r, added[0].color.g, added[0].color.b)
    assert len(set(colours.values())) == 3
    # The concave true obstacle: a triangle list whose area is the polygon's, not its hull's.
    _, last = decoded['/viz/obstacles/truth'][-1]
    ell = next(m for m in last.markers if m.text == 'ell')
    assert ell.type == 11                        # TRIANGLE_LIST
    corners = [(p.x, p.y) for p in ell.points]
    area = sum(shapely.Polygon(corners[i:i + 3]).area for i in range(0, len(corners), 3))
    assert area == pytest.approx(shapely.Polygon(ELL).area, rel=1e-9)
    assert shapely.Polygon(ELL).area < shapely.Polygon(ELL).convex_hull.area - 0.5
    outline = next(m for m in decoded['/viz/obstacles/detected'][-1][1].markers
                   if m.text == 'ell')
    assert outline.type == 4 and len(outline.points) == len(ELL) + 1   # closed LINE_STRIP


def test_tf_map_to_base_link_at_every_odometry_step(decoded):
    odom = [(stamp(m.header), m.pose.pose.position) for _, m in decoded['/odom']]
    tf = {}
    for schema, msg in decoded['/tf']:
        assert schema == 'tf2_msgs/msg/TFMessage'
        (transform,) = msg.transforms
        assert (transform.header.frame_id, transform.child_frame_id) == ('map', 'base_link')
        tf[stamp(transform.header)] = transform.transform.translation
    assert len(odom) > 50
    for t, position in odom:
        assert (tf[t].x, tf[t].y) == (position.x, position.y)


def test_robot_and_perception_discs_follow_base_link(decoded):
    (_, array), = decoded['/viz/robot']
    discs = {m.ns: m for m in array.markers}
    assert set(discs) == {'robot', 'perception'}
    for marker, radius in ((discs['robot'], 0.3), (discs['perception'], 5.0)):
        assert marker.header.frame_id == 'base_link' and marker.frame_locked
        assert marker.scale.x == marker.scale.y == pytest.approx(2 * radius)


def test_leg_targets_are_the_controller_targets(decoded):
    targets = {(m.leg_target.x, m.leg_target.y) for _, m in decoded['/controller/state']}
    _, last = decoded['/viz/leg_targets'][-1]
    markers = {m.ns: m for m in last.markers}
    assert {(p.x, p.y) for p in markers['leg_targets'].points} == targets
    state = decoded['/controller/state'][-1][1]
    current = markers['current_target'].pose.position
    assert (current.x, current.y) == (state.leg_target.x, state.leg_target.y)


def _field(message, path):
    for name in path:
        message = getattr(message, name)
    return message


def test_the_foxglove_layout_names_recorded_topics_and_fields(decoded):
    layout = json.loads((ROOT / 'docs/foxglove_layout.json').read_text())
    panels = layout['configById']
    (three_d,) = [p for k, p in panels.items() if k.startswith('3D!')]
    assert three_d['followTf'] == 'map'
    for topic in three_d['topics']:
        assert topic in decoded, topic
    plotted = [s['value'] for k, p in panels.items() if k.startswith('Plot!')
               for s in p['paths']]
    # The true clearance is the referee's (simulator side); the safety node's is to the map.
    assert {'/cmd_force.wrench.force.x', '/safety/status.d_rob',
            '/safety/status.margin', '/referee/status.min_clearance'} <= set(plotted)
    for value in plotted:
        topic, *path = value.split('.')
        assert isinstance(_field(decoded[topic][-1][1], path), float), value

    def ids(node):
        return [node] if isinstance(node, str) else ids(node['first']) + ids(node['second'])
    assert sorted(ids(layout['layout'])) == sorted(panels)


def test_report_video_has_one_frame_per_interval(recording, tmp_path, decoded):
    out = tmp_path / 'report'
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'report', str(recording), '--out',
                           str(out), '--video', '--frame-interval', '0.5'],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    t_end = stamp(decoded['/odom'][-1][1].header)
    frames = int(t_end / 0.5 + 1e-9) + 1
    assert 'video' in proc.stderr and f'{frames}/{frames} frames' in proc.stderr
    video = out / 'run.gif'
    assert video.exists()
    odom = [(stamp(m.header), m.pose.pose.position) for _, m in decoded['/odom']]
    with Image.open(video) as gif:
        assert gif.n_frames == frames
        for frame in range(frames):
            gif.seek(frame)
            t = frame * 0.5
            expected = [p for s, p in odom if s <= t + 1e-9][-1]
            x, y = robot_in_frame(np.asarray(gif.convert('RGB'), dtype=float), (-10, 10),
                                  (-10, 10))
            # 20 m over ~500 pixels: a pixel is 4 cm.
            assert abs(x - expected.x) < 0.1 and abs(y - expected.y) < 0.1, (frame, x, y)


def robot_in_frame(rgb, xlim, ylim):
    """Where a frame draws the robot, in metres: the centroid of its pure blue disc, mapped
    through the axes box (the black spines) to the axes' data limits."""
    dark = rgb.sum(axis=2) < 120
    columns = np.flatnonzero(dark.sum(axis=0) > 0.5 * rgb.shape[0])
    rows = np.flatnonzero(dark.sum(axis=1) > 0.5 * rgb.shape[1])
    left, right, top, bottom = columns.min(), columns.max(), rows.min(), rows.max()
    blue = (rgb[..., 2] > 200) & (rgb[..., 0] < 60) & (rgb[..., 1] < 60)
    assert blue.sum() > 20, 'no robot disc in the frame'
    r, c = np.nonzero(blue)
    x = xlim[0] + (c.mean() - left) / (right - left) * (xlim[1] - xlim[0])
    y = ylim[1] - (r.mean() - top) / (bottom - top) * (ylim[1] - ylim[0])
    return x, y
