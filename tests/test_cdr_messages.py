"""Messages built or read as CDR bytes in the hot paths, against rclpy's own serialisation."""

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from visualization_msgs.msg import MarkerArray

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
