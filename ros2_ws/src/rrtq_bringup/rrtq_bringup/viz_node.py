"""Visualisation node: what Foxglove's 3D panel draws natively, from the graph's topics.

It reads the graph and publishes only for people (no node reads what it writes), so it is
outside the lock-step chain and a run's other topics are the same with or without it:

- ``/tf``: ``map`` -> ``base_link`` at every odometry stamp (tf2_msgs/TFMessage);
- ``/viz/obstacles/{truth,detected,augmented}``: each obstacle set as a MarkerArray, one
  marker per obstacle (namespace and colour per set, ``text`` = the obstacle's id), with a
  DELETE for every obstacle that left the set since its last message;
- ``/viz/robot``: the robot's disc and the perception disc, in ``base_link`` and
  frame-locked (the 3D panel moves them with ``/tf``);
- ``/viz/leg_targets``: the leg targets met so far and the current one.

The plan (nav_msgs/Path), the tree (/planner/tree) and /odom are drawn as they are.
Every marker is stamped with the stamp of the message it comes from.
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point, TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState, ObstacleArray
from std_msgs.msg import ColorRGBA
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from rrtq_bringup.viz import (AUGMENTED, CURRENT_TARGET_COLOR, CURRENT_TARGET_NS, DETECTED,
                              LEG_TARGETS_COLOR, LEG_TARGETS_NS, PERCEPTION_COLOR,
                              PERCEPTION_NS, RGBA, ROBOT_COLOR, ROBOT_NS, TRUTH, LayerStyle,
                              LegTargets, MarkerLayer, Shape, VizConfig, shape_points)
from rrtq_common import qos, topics
from rrtq_common.conversions import (MAP_FRAME, ROBOT_FRAME, OdometryReading, obstacle_array,
                                     read_odometry)
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.params import declare_config, spin_node

LAYERS = ((topics.OBSTACLES_TRUTH, topics.VIZ_TRUTH, TRUTH),
          (topics.OBSTACLES_DETECTED, topics.VIZ_DETECTED, DETECTED),
          (topics.OBSTACLES_AUGMENTED, topics.VIZ_AUGMENTED, AUGMENTED))


def _color(rgba: RGBA) -> ColorRGBA:
    return ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _marker(header, ns: str, marker_id: int, kind: int, rgba: RGBA) -> Marker:
    marker = Marker(header=header, ns=ns, id=marker_id, type=kind, action=Marker.ADD)
    marker.pose.orientation.w = 1.0
    marker.color = _color(rgba)
    return marker


def _points(xy: np.ndarray, z: float) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=z) for x, y in xy]


def layer_msg(msg: ObstacleArray, style: LayerStyle, layer: MarkerLayer) -> MarkerArray:
    """One obstacle set as markers of ``style``: ADD what is present, DELETE what left."""
    obstacles = obstacle_array(msg)
    present, deleted = layer.update(name for name, _ in obstacles)
    kind = Marker.TRIANGLE_LIST if style.shape is Shape.FILL else Marker.LINE_STRIP
    markers = []
    for (marker_id, name), (_, polygon) in zip(present, obstacles):
        marker = _marker(msg.header, style.ns, marker_id, kind, style.color)
        marker.scale.x = style.width if style.shape is Shape.OUTLINE else 1.0
        marker.scale.y = marker.scale.z = 1.0
        marker.text = name
        marker.points = _points(shape_points(style, polygon), style.z)
        markers.append(marker)
    for marker_id in deleted:
        markers.append(Marker(header=msg.header, ns=style.ns, id=marker_id,
                              action=Marker.DELETE))
    return MarkerArray(markers=markers)


class VizNode(Node):
    """Publish /tf and the markers of the 3D panel from the graph's own topics."""

    def __init__(self, **kwargs) -> None:
        super().__init__('viz', **NODE_OPTIONS, **kwargs)
        self.config = declare_config(self, VizConfig)
        self.tf_pub = self.create_publisher(TFMessage, topics.TF, qos.STREAM)
        self.robot_pub = self.create_publisher(MarkerArray, topics.VIZ_ROBOT, qos.LATCHED)
        self.legs_pub = self.create_publisher(MarkerArray, topics.VIZ_LEG_TARGETS, qos.LATCHED)
        # /odom as bytes, read as the step's nodes read it (rrtq_common.inputs).
        self.create_subscription(Odometry, topics.ODOM, self.on_odom_bytes, qos.STREAM, raw=True)
        self.create_subscription(ControllerState, topics.CONTROLLER_STATE, self.on_state,
                                 qos.STREAM)
        for source, target, style in LAYERS:
            publisher = self.create_publisher(MarkerArray, target, qos.LATCHED)
            self.create_subscription(ObstacleArray, source,
                                     self._layer_callback(publisher, style), qos.LATCHED)
        self.legs = LegTargets()
        self._robot_sent = False

    def _layer_callback(self, publisher, style: LayerStyle):
        layer = MarkerLayer()
        return lambda msg: publisher.publish(layer_msg(msg, style, layer))

    def on_odom_bytes(self, data: bytes) -> None:
        self.on_odom(read_odometry(data))

    def on_odom(self, msg: OdometryReading) -> None:
        transform = TransformStamped(header=msg.header, child_frame_id=ROBOT_FRAME)
        transform.header.frame_id = MAP_FRAME
        translation = transform.transform.translation
        translation.x, translation.y, translation.z = msg.position
        rotation = transform.transform.rotation
        rotation.x, rotation.y, rotation.z, rotation.w = msg.orientation
        self.tf_pub.publish(TFMessage(transforms=[transform]))
        if not self._robot_sent:
            self._robot_sent = True
            self.robot_pub.publish(self._robot_markers(msg))

    def _robot_markers(self, odom: OdometryReading) -> MarkerArray:
        markers = []
        for ns, radius, height, rgba in (
                (ROBOT_NS, self.config.robot_radius, 0.3, ROBOT_COLOR),
                (PERCEPTION_NS, self.config.perception_radius, 0.01, PERCEPTION_COLOR)):
            marker = _marker(odom.header, ns, 0, Marker.CYLINDER, rgba)
            marker.header.frame_id = ROBOT_FRAME
            marker.frame_locked = True
            marker.scale.x = marker.scale.y = 2.0 * radius
            marker.scale.z = height
            markers.append(marker)
        return MarkerArray(markers=markers)

    def on_state(self, msg: ControllerState) -> None:
        if msg.variant == 'open_loop':
            return
        if not self.legs.update(msg.leg_index, (msg.leg_target.x, msg.leg_target.y)):
            return
        header = msg.header
        header.frame_id = MAP_FRAME
        past = _marker(header, LEG_TARGETS_NS, 0, Marker.SPHERE_LIST, LEG_TARGETS_COLOR)
        past.scale.x = past.scale.y = past.scale.z = 0.25
        past.points = _points(np.array(self.legs.targets), 0.1)
        current = _marker(header, CURRENT_TARGET_NS, 0, Marker.SPHERE, CURRENT_TARGET_COLOR)
        current.scale.x = current.scale.y = current.scale.z = 0.5
        current.pose.position = Point(x=msg.leg_target.x, y=msg.leg_target.y, z=0.25)
        self.legs_pub.publish(MarkerArray(markers=[past, current]))


def main(args: list[str] | None = None) -> None:
    spin_node(VizNode, args)


if __name__ == '__main__':
    main()
