"""Messages <-> core types that every node shares: time, odometry, obstacles, paths.

Each package keeps its own ``conversions`` module for its own messages; this one holds
the types that cross packages.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping
from typing import NamedTuple

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point32, Polygon, PoseStamped
from nav_msgs.msg import Odometry, Path
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Header
from rrtq_msgs.msg import Obstacle, ObstacleArray

from rrtq_common.lockstep import OnChange
from rrtq_common.scan import PerceptionConfig, beam_angles

MAP_FRAME = 'map'
ROBOT_FRAME = 'base_link'


def time_msg(ns: int) -> Time:
    """A stamp from integer nanoseconds."""
    return Time(sec=ns // 10**9, nanosec=ns % 10**9)


def stamp_ns(stamp: Time) -> int:
    """Integer nanoseconds of a stamp (lock-step compares them exactly)."""
    return stamp.sec * 10**9 + stamp.nanosec


def clock_msg(ns: int) -> Clock:
    """/clock at ``ns``."""
    return Clock(clock=time_msg(ns))


def odometry_msg(ns: int, x: np.ndarray, position_variance: float = 0.0,
                 velocity_variance: float = 0.0) -> Odometry:
    """Odometry of the planar robot: position and velocity in ``map``.

    The robot has no heading state (a point mass), so ``base_link`` is kept parallel
    to ``map`` (identity orientation) and the twist, expressed in ``base_link`` per
    nav_msgs' convention, equals the velocity in ``map``. The variances (m², m²/s²) go on
    the covariances' diagonal for x and y (row-major 6 x 6: entries 0 and 7); the rest of
    both covariances stays zero.
    """
    msg = Odometry()
    if position_variance:
        msg.pose.covariance[0] = msg.pose.covariance[7] = float(position_variance)
    if velocity_variance:
        msg.twist.covariance[0] = msg.twist.covariance[7] = float(velocity_variance)
    msg.header.stamp = time_msg(ns)
    msg.header.frame_id = MAP_FRAME
    msg.child_frame_id = ROBOT_FRAME
    msg.pose.pose.position.x = float(x[0])
    msg.pose.pose.position.y = float(x[1])
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x = float(x[2])
    msg.twist.twist.linear.y = float(x[3])
    return msg


class OdometryReading(NamedTuple):
    """What the graph's nodes read of an /odom message (:func:`read_odometry`)."""

    header: Header
    position: tuple[float, float, float]             # pose.pose.position, m
    orientation: tuple[float, float, float, float]   # pose.pose.orientation x, y, z, w
    velocity: tuple[float, float]                    # twist.twist.linear x, y, m/s
    variance: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    """The covariances' diagonal for x, y (m²) and v_x, v_y (m²/s²): what the odometry says
    of its own noise."""


_STAMP = struct.Struct('<iI')
_LENGTH = struct.Struct('<I')
_POSE = struct.Struct('<7d')
_LINEAR = struct.Struct('<2d')
_COVARIANCE = 36 * 8
_DIAGONAL = struct.Struct('<d48xd')                  # covariance entries 0 and 7 (x, y)
_TWIST = 6 * 8


def read_odometry(data: bytes) -> OdometryReading:
    """An /odom message's header, pose and velocity, read from its CDR bytes.

    Every node of a step reads /odom; deserialising the whole nav_msgs/Odometry (ten nested
    messages and two covariance arrays) cost ~30 us per reader, reading these fields a few
    struct unpacks. The doubles are the message's own, bit for bit.
    """
    if data[:2] != b'\x00\x01':
        raise ValueError('not little-endian CDR')
    body = memoryview(data)[4:]          # alignment counts from after the encapsulation

    def string(at: int) -> tuple[str, int]:
        at += -at % 4
        (size,) = _LENGTH.unpack_from(body, at)
        return bytes(body[at + 4:at + 3 + size]).decode(), at + 4 + size

    sec, nanosec = _STAMP.unpack_from(body, 0)
    frame_id, at = string(8)
    _child, at = string(at)
    at += -at % 8
    pose = _POSE.unpack_from(body, at)
    position = _DIAGONAL.unpack_from(body, at + _POSE.size)
    twist = at + _POSE.size + _COVARIANCE
    linear = _LINEAR.unpack_from(body, twist)
    velocity = _DIAGONAL.unpack_from(body, twist + _TWIST)
    return OdometryReading(Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id),
                           pose[:3], pose[3:], linear, position + velocity)


def odometry_variance(msg: Odometry | OdometryReading) -> np.ndarray:
    """The variance of (p_x, p_y, v_x, v_y)'s measurement: the covariances' diagonal."""
    if isinstance(msg, OdometryReading):
        return np.array(msg.variance, dtype=float)
    return np.array([msg.pose.covariance[0], msg.pose.covariance[7],
                     msg.twist.covariance[0], msg.twist.covariance[7]], dtype=float)


def odometry_state(msg: Odometry | OdometryReading) -> np.ndarray:
    """(p_x, p_y, v_x, v_y) from an odometry message or its reading."""
    if isinstance(msg, OdometryReading):
        return np.array([msg.position[0], msg.position[1], msg.velocity[0], msg.velocity[1]])
    return np.array([msg.pose.pose.position.x, msg.pose.pose.position.y,
                     msg.twist.twist.linear.x, msg.twist.twist.linear.y])


def polygon_msg(vertices: np.ndarray) -> Polygon:
    """A polygon (k, 2), m."""
    return Polygon(points=[Point32(x=float(x), y=float(y), z=0.0) for x, y in vertices])


def polygon_array(msg: Polygon) -> np.ndarray:
    """(k, 2) vertices, m."""
    return np.array([[p.x, p.y] for p in msg.points], dtype=float).reshape(-1, 2)


def obstacle_array_msg(ns: int, obstacles: Iterable[tuple[str, np.ndarray]],
                       margin: float = 0.0,
                       margins: Mapping[str, float] | None = None) -> ObstacleArray:
    """(id, polygon) pairs in ``map``, each marked as grown by ``margin`` (m).

    ``margins``: an obstacle's own margin by id where it has one (learned_bound grows each
    obstacle by the margin of where it is).
    """
    own = margins or {}
    msg = ObstacleArray(margin=float(margin), obstacles=[
        Obstacle(id=oid, polygon=polygon_msg(poly), margin=float(own.get(oid, margin)))
        for oid, poly in obstacles])
    msg.header.stamp = time_msg(ns)
    msg.header.frame_id = MAP_FRAME
    return msg


def obstacle_array(msg: ObstacleArray) -> list[tuple[str, np.ndarray]]:
    """(id, polygon) pairs."""
    return [(o.id, polygon_array(o.polygon)) for o in msg.obstacles]


def path_msg(ns: int, waypoints: Iterable[tuple[float, float]]) -> Path:
    """A path in ``map`` through ``waypoints`` (m), poses with identity orientation."""
    msg = Path()
    msg.header.stamp = time_msg(ns)
    msg.header.frame_id = MAP_FRAME
    for x, y in waypoints:
        pose = PoseStamped()
        pose.header = msg.header
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation.w = 1.0
        msg.poses.append(pose)
    return msg


def path_waypoints(msg: Path) -> np.ndarray:
    """(K, 2) waypoints of a path, m."""
    return np.array([[p.pose.position.x, p.pose.position.y] for p in msg.poses],
                    dtype=float).reshape(-1, 2)


def changed_path(msg: Path | None) -> OnChange[np.ndarray] | None:
    """A latched path as an on-change input: its stamp, its waypoints read on demand."""
    if msg is None:
        return None
    return OnChange(stamp_ns(msg.header.stamp), lambda: path_waypoints(msg))


def changed_obstacles(msg: ObstacleArray | None) -> OnChange[list[tuple[str, np.ndarray]]] | None:
    """A latched obstacle set as an on-change input: its stamp, the polygons read on demand."""
    if msg is None:
        return None
    return OnChange(stamp_ns(msg.header.stamp), lambda: obstacle_array(msg))


def laser_scan_msg(ns: int, ranges: np.ndarray, config: PerceptionConfig) -> LaserScan:
    """A 360° scan in ``base_link`` (REP-117: ``inf`` for no return), stamped ``ns``."""
    angles = beam_angles(config.beams)
    msg = LaserScan(angle_min=float(angles[0]), angle_max=float(angles[-1]),
                    angle_increment=float(config.angle_increment), time_increment=0.0,
                    scan_time=float(1.0 / config.rate), range_min=0.0,
                    range_max=float(config.range_max or 0.0),
                    ranges=np.asarray(ranges, dtype=np.float32))
    msg.header.stamp = time_msg(ns)
    msg.header.frame_id = ROBOT_FRAME
    return msg


def laser_scan_ranges(msg: LaserScan) -> np.ndarray:
    """The ranges, m, as float64; below ``range_min`` or above ``range_max``: ``inf``."""
    ranges = np.asarray(msg.ranges, dtype=float)
    return np.where((ranges >= msg.range_min) & (ranges <= msg.range_max), ranges, np.inf)
