"""Messages built or read as CDR bytes in the hot paths, against rclpy's own serialisation."""

import numpy as np
import pytest
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from visualization_msgs.msg import MarkerArray

from rrtq_common import conversions as conv
from rrtq_planner import conversions as planner_conv


@pytest.mark.parametrize('edges', [0, 1, 2, 5, 3000])
def test_tree_bytes_are_the_tree_message(edges):
    rng = np.random.default_rng(edges)
    segments = rng.uniform(-50.0, 50.0, (edges, 2, 2))
    stamp_ns = 12 * 10**9 + 345_678_901
    reference = serialize_message(planner_conv.tree_msg(stamp_ns, segments))
    fast = planner_conv.tree_bytes(stamp_ns, segments)
    # The same message: every field, every point (z = 0).
    decoded = deserialize_message(fast, MarkerArray)
    assert decoded == deserialize_message(reference, MarkerArray)
    points = decoded.markers[0].points
    assert len(points) == 2 * edges
    assert [(p.x, p.y, p.z) for p in points] == [
        (x, y, 0.0) for x, y in segments.reshape(-1, 2).tolist()]
    # The same bytes but for the padding, which is zero here (rclpy's serialize_message
    # leaves whatever was in its buffer; a publisher's buffer starts zeroed).
    assert len(fast) == len(reference)
    assert all(a == b or b == 0 for a, b in zip(reference, fast))


def test_tree_bytes_build_no_point_objects(monkeypatch):
    built = []
    monkeypatch.setattr(planner_conv, 'Point', lambda **kw: built.append(kw))
    planner_conv.tree_bytes(0, np.zeros((100, 2, 2)))
    assert built == []


@pytest.mark.parametrize('frame_id, child_frame_id', [
    ('map', 'base_link'), ('', ''), ('a', 'abcdefg'), ('odom_frame_long', 'x' * 13)])
def test_read_odometry_reads_what_deserialising_gives(frame_id, child_frame_id):
    # Frame ids of every length modulo 8: the doubles' alignment after the strings varies.
    rng = np.random.default_rng(len(frame_id) + 10 * len(child_frame_id))
    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1234, 567_890_123
    msg.header.frame_id, msg.child_frame_id = frame_id, child_frame_id
    v = rng.normal(size=13)
    pose, twist = msg.pose.pose, msg.twist.twist
    pose.position.x, pose.position.y, pose.position.z = v[:3]
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = v[3:7]
    twist.linear.x, twist.linear.y, twist.linear.z = v[7:10]
    twist.angular.x, twist.angular.y, twist.angular.z = v[10:]
    msg.pose.covariance = rng.normal(size=36)
    msg.twist.covariance = rng.normal(size=36)
    data = serialize_message(msg)
    reading = conv.read_odometry(data)
    decoded = deserialize_message(data, Odometry)
    assert reading.header == decoded.header
    p, q, lin = decoded.pose.pose.position, decoded.pose.pose.orientation, decoded.twist.twist.linear
    assert reading.position == (p.x, p.y, p.z)
    assert reading.orientation == (q.x, q.y, q.z, q.w)
    assert reading.velocity == (lin.x, lin.y)
    assert conv.odometry_state(reading).tobytes() == conv.odometry_state(decoded).tobytes()
    # the covariances' diagonal for x, y and v_x, v_y: what the controller's observer smooths by
    assert conv.odometry_variance(reading).tobytes() == conv.odometry_variance(decoded).tobytes()
    assert conv.odometry_variance(reading).tolist() == [
        decoded.pose.covariance[0], decoded.pose.covariance[7],
        decoded.twist.covariance[0], decoded.twist.covariance[7]]


def test_read_odometry_of_the_simulators_message():
    x = np.array([-14.999999999999998, 3.25e-7, 0.1 + 0.2, -1e-300])
    reading = conv.read_odometry(serialize_message(conv.odometry_msg(66_950_000_000, x)))
    assert conv.stamp_ns(reading.header.stamp) == 66_950_000_000
    assert reading.header.frame_id == conv.MAP_FRAME
    assert conv.odometry_state(reading).tobytes() == x.tobytes()
    assert reading.orientation == (0.0, 0.0, 0.0, 1.0)


def test_read_odometry_refuses_big_endian():
    data = bytearray(serialize_message(conv.odometry_msg(0, np.zeros(4))))
    data[1] = 0
    with pytest.raises(ValueError):
        conv.read_odometry(bytes(data))


def test_odometry_carries_its_frames_and_the_measurements_variances():
    """REP-103/105: pose and velocity in ``map``, child ``base_link``; σ_p² and σ_v² on the
    covariances' x and y diagonal (row-major 6 x 6), every other entry zero; the default, an
    exact state, has both covariances zero, as before the noise existed."""
    x = np.array([1.5, -2.0, 0.25, 0.5])
    msg = conv.odometry_msg(3 * 10**9 + 50_000_000, x, 0.04, 0.0025)
    assert (msg.header.frame_id, msg.child_frame_id) == ('map', 'base_link')
    decoded = deserialize_message(serialize_message(msg), Odometry)
    pose, twist = np.reshape(decoded.pose.covariance, (6, 6)), np.reshape(
        decoded.twist.covariance, (6, 6))
    assert np.array_equal(pose, np.diag([0.04, 0.04, 0, 0, 0, 0]))
    assert np.array_equal(twist, np.diag([0.0025, 0.0025, 0, 0, 0, 0]))
    assert conv.odometry_state(decoded).tolist() == x.tolist()
    exact = conv.odometry_msg(0, x)
    assert not np.any(exact.pose.covariance) and not np.any(exact.twist.covariance)
    assert serialize_message(exact) == serialize_message(conv.odometry_msg(0, x, 0.0, 0.0))
