"""Messages <-> core types of the planner and the safety node."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point
from rrtq_msgs.msg import ControllerState, PlannerStats, SafetyStatus
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from rrtq_common.conversions import MAP_FRAME, time_msg

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


def tree_msg(stamp_ns: int, segments: np.ndarray) -> MarkerArray:
    """The tree's parent edges (E, 2, 2) as one line list, for display."""
    marker = Marker(ns='rrtx_tree', id=0, type=Marker.LINE_LIST, action=Marker.ADD)
    marker.header.stamp = time_msg(stamp_ns)
    marker.header.frame_id = MAP_FRAME
    marker.pose.orientation.w = 1.0
    marker.scale.x = 0.03
    marker.color = ColorRGBA(r=0.6, g=0.6, b=0.6, a=0.8)
    # One tolist() instead of a float() per coordinate: a third of the time for a large tree.
    marker.points = [Point(x=x, y=y) for x, y in
                     np.asarray(segments, dtype=float).reshape(-1, 2).tolist()]
    return MarkerArray(markers=[marker])


def leg_of(state: ControllerState | None) -> Leg | None:
    """The leg a controller state reports (None before the first state)."""
    if state is None:
        return None
    return Leg(state.leg_index, (state.leg_start.x, state.leg_start.y),
               (state.leg_target.x, state.leg_target.y), state.d0)


def safety_status_msg(header: Header, step: SafetyStep) -> SafetyStatus:
    """/safety/status of one step; ``augmented_stamp`` names the latest augmented set."""
    status = SafetyStatus(
        d_rob=step.d_rob, d_rob_max=step.d_rob_max, margin=step.margin,
        min_clearance=step.clearance, nearest_obstacle=step.nearest, collision=step.collision,
        leg_index=step.leg_index, augmented_stamp=time_msg(step.augmented_stamp_ns))
    status.header = header
    return status
