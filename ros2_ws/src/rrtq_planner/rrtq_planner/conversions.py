"""Messages <-> core types of the planner and the safety node."""

from __future__ import annotations

import struct

import numpy as np
from geometry_msgs.msg import Point, Vector3
from rrtq_msgs.msg import (ControllerState, DisturbanceEstimate, GuidanceReference, PlannerStats,
                           SafetyStatus)
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from rrtq_common.actor import actor_gain
from rrtq_common.conversions import MAP_FRAME, time_msg

from .margins.learned_data import FieldEstimate
from .margins.policy import LegInfo, MarginSample, MarginStatus
from .guidance import GuidanceOutput
from .rrtx_config import PlanStatus
from .safety import Leg, SafetyStep
from .session import Cycle

STATUS = {PlanStatus.SEARCHING: PlannerStats.STATUS_SEARCHING, PlanStatus.FOUND:
          PlannerStats.STATUS_FOUND, PlanStatus.NO_PATH: PlannerStats.STATUS_NO_PATH}


def stats_msg(cycle: Cycle) -> PlannerStats:
    """/planner/stats of one cycle; ``plan_stamp`` names the latest /plan."""
    stats = PlannerStats(
        status=STATUS[cycle.plan.status], nodes=cycle.nodes, path_cost=float(cycle.plan.cost),
        replans=cycle.replans, last_repair_ms=cycle.repair_ms, iterations=cycle.iterations,
        cycle_ms=cycle.cycle_ms, ball_radius=cycle.ball_radius,
        plan_stamp=time_msg(cycle.plan_stamp_ns))
    stats.header.stamp = time_msg(cycle.stamp_ns)
    stats.header.frame_id = MAP_FRAME
    return stats


_TREE_NS = 'rrtx_tree'
_TREE_WIDTH = 0.03                      # m, scale.x of the line list
_TREE_COLOR = (0.6, 0.6, 0.6, 0.8)      # r, g, b, a


def tree_msg(stamp_ns: int, segments: np.ndarray) -> MarkerArray:
    """The tree's parent edges (E, 2, 2) as one line list, for display."""
    marker = Marker(ns=_TREE_NS, id=0, type=Marker.LINE_LIST, action=Marker.ADD)
    marker.header.stamp = time_msg(stamp_ns)
    marker.header.frame_id = MAP_FRAME
    marker.pose.orientation.w = 1.0
    marker.scale.x = _TREE_WIDTH
    marker.color = ColorRGBA(r=_TREE_COLOR[0], g=_TREE_COLOR[1], b=_TREE_COLOR[2],
                             a=_TREE_COLOR[3])
    # One tolist() instead of a float() per coordinate: a third of the time for a large tree.
    marker.points = [Point(x=x, y=y) for x, y in
                     np.asarray(segments, dtype=float).reshape(-1, 2).tolist()]
    return MarkerArray(markers=[marker])


class _Cdr:
    """A little-endian CDR buffer (XCDR1, as rmw_fastrtps writes it), padding zeroed."""

    def __init__(self) -> None:
        self.buf = bytearray(b'\x00\x01\x00\x00')     # encapsulation: CDR_LE

    def put(self, fmt: str, *values: float | int, align: int) -> None:
        self.buf += bytes(-(len(self.buf) - 4) % align)  # alignment counts from the data
        self.buf += struct.pack('<' + fmt, *values)

    def string(self, text: str) -> None:
        data = text.encode() + b'\x00'
        self.put('I', len(data), align=4)
        self.buf += data

    def header(self, stamp_ns: int, frame_id: str) -> None:
        self.put('iI', *divmod(stamp_ns, 10**9), align=4)
        self.string(frame_id)


def tree_bytes(stamp_ns: int, segments: np.ndarray) -> bytes:
    """:func:`tree_msg` serialised as the publisher would: the same bytes, without a Point each.

    A tree of 3000 nodes is 6000 points, and their Python objects (and the C conversion of
    each) cost more than the rest of a lock-step cycle; here the points are one array's
    bytes. The fields in the order of visualization_msgs/Marker, every padding byte zero.
    """
    points = np.asarray(segments, dtype=float).reshape(-1, 2)
    out = _Cdr()
    out.put('I', 1, align=4)                                 # markers[]: one
    out.header(stamp_ns, MAP_FRAME)
    out.string(_TREE_NS)
    out.put('iii', 0, Marker.LINE_LIST, Marker.ADD, align=4)  # id, type, action
    out.put('7d', 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, align=8)  # pose: origin, identity
    out.put('3d', _TREE_WIDTH, 0.0, 0.0, align=8)            # scale
    out.put('4f', *_TREE_COLOR, align=4)
    out.put('iI?', 0, 0, False, align=4)                     # lifetime, frame_locked
    out.put('I', points.shape[0], align=4)                   # points[]
    if points.shape[0]:
        out.put('', align=8)
        xyz = np.zeros((points.shape[0], 3), dtype='<f8')
        xyz[:, :2] = points
        out.buf += xyz.tobytes()
    out.put('I', 0, align=4)                                 # colors[]
    out.string('')                                           # texture_resource
    out.header(0, '')                                        # texture: header, format, data[]
    out.string('')
    out.put('I', 0, align=4)
    out.put('I', 0, align=4)                                 # uv_coordinates[]
    out.string('')                                           # text
    out.string('')                                           # mesh_resource
    out.string('')                                           # mesh_file: filename, data[]
    out.put('I', 0, align=4)
    out.put('?', False, align=1)                             # mesh_use_embedded_materials
    return bytes(out.buf)


def leg_of(state: ControllerState | None) -> Leg | None:
    """The leg a controller state reports (None before the first state)."""
    if state is None:
        return None
    return Leg(state.leg_index, (state.leg_start.x, state.leg_start.y),
               (state.leg_target.x, state.leg_target.y), state.d0)


def safety_status_msg(header: Header, step: SafetyStep, margin: MarginStatus) -> SafetyStatus:
    """/safety/status of one step; ``augmented_stamp`` names the latest augmented set."""
    status = SafetyStatus(
        d_rob=step.d_rob, d_rob_max=step.d_rob_max, margin=step.margin,
        min_clearance=step.clearance, nearest_obstacle=step.nearest, collision=step.collision,
        leg_index=step.leg_index, augmented_stamp=time_msg(step.augmented_stamp_ns),
        # int() and float(): the policies' counts may be numpy scalars, which the C
        # conversion of a uint32 field rejects.
        margin_mode=margin.mode.value, leg_margin=float(margin.leg_margin),
        bound=float(margin.bound), confidence=float(margin.confidence),
        samples=int(margin.samples), violations=int(margin.violations),
        bound_violations=int(margin.bound_violations),
        leg_deviation=float(margin.leg_deviation), legs=int(margin.legs),
        leg_tube=float(margin.leg_tube), scale=float(margin.scale),
        leg_refuted=bool(margin.leg_refuted),
        obstacle_distance=float(step.obstacle_distance),
        obstacle_direction=Vector3(x=step.obstacle_direction[0], y=step.obstacle_direction[1]),
        ahead_distance=float(step.ahead_distance),
        ahead_direction=Vector3(x=step.ahead_direction[0], y=step.ahead_direction[1]))
    status.header = header
    return status


def disturbance_estimate_msg(stamp_ns: int, est: FieldEstimate) -> DisturbanceEstimate:
    """/safety/disturbance_estimate of one fit (learned_bound)."""
    mean = np.asarray(est.mean, dtype=np.float32)
    band = np.asarray(est.band, dtype=np.float32)
    msg = DisturbanceEstimate(
        x0=float(est.origin[0]), y0=float(est.origin[1]), spacing=float(est.spacing),
        nx=int(est.shape[0]), ny=int(est.shape[1]),
        mean_x=mean[:, 0].tolist(), mean_y=mean[:, 1].tolist(),
        band_x=band[:, 0].tolist(), band_y=band[:, 1].tolist(),
        supported=[bool(v) for v in est.supported],
        bound=float(est.bound), confidence=float(est.confidence), samples=int(est.samples))
    msg.header.stamp = time_msg(stamp_ns)
    msg.header.frame_id = MAP_FRAME
    return msg


def margin_sample(t: float, x: np.ndarray, state: ControllerState | None, n: int, m: int,
                  gain: bool) -> MarginSample:
    """What the margin policy is fed at a step: the state, and the controller's of the step before.

    ``gain``: reconstruct K̂(τ) (learned_bound only: the others do not read it).
    """
    if state is None:
        return MarginSample(t, x)
    leg = LegInfo(int(state.leg_index), np.array([state.leg_start.x, state.leg_start.y]),
                  np.array([state.leg_target.x, state.leg_target.y]), float(state.d0))
    k = (actor_gain(state.actor_weights, state.time_rates, state.time_powers, state.horizon,
                    n, m) if gain else None)
    return MarginSample(t, x, leg, np.asarray(state.command, dtype=float),
                        np.asarray(state.probing_noise, dtype=float), k, float(state.horizon))


def reference_msg(stamp_ns: int, out: GuidanceOutput, dt: float) -> GuidanceReference:
    """/guidance/reference of one cycle: samples every ``dt`` (s) from the step's stamp."""
    ref = out.reference
    msg = GuidanceReference(
        status=str(out.status), dt=float(dt), rollout=out.rollout,
        positions=[Point(x=float(x), y=float(y)) for x, y in ref.positions],
        velocities=[Vector3(x=float(x), y=float(y)) for x, y in ref.velocities],
        obstacles_stamp=time_msg(out.obstacles_stamp_ns), plan_stamp=time_msg(out.plan_stamp_ns))
    msg.header.stamp = time_msg(stamp_ns)
    msg.header.frame_id = MAP_FRAME
    return msg
