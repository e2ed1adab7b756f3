"""Messages <-> core types of the simulator side: the disturbance, the perception and referee statuses."""

from __future__ import annotations

import numpy as np
from std_msgs.msg import Header
from rrtq_msgs.msg import Disturbance, PerceptionStatus, PlantContact, RefereeStatus

from rrtq_common.conversions import MAP_FRAME, time_msg
from rrtq_sim.perception import ObstacleEvent, Observation
from rrtq_sim.referee import Judgement


def disturbance_msg(ns: int, model: str, value: np.ndarray) -> Disturbance:
    """The disturbance d (its model named) in ``map`` at ``ns``."""
    msg = Disturbance(model=model, value=[float(v) for v in value])
    msg.header.stamp = time_msg(ns)
    msg.header.frame_id = MAP_FRAME
    return msg


def perception_status_msg(header: Header, detected_stamp_ns: int, known: int,
                          seen: Observation) -> PerceptionStatus:
    """The step's status: the stamp of the latest map, its size, what changed."""
    return PerceptionStatus(
        header=header, detected_stamp=time_msg(detected_stamp_ns), known=known,
        in_range=seen.in_range,
        detected=[oid for e, oid in seen.events if e is ObstacleEvent.DETECTED],
        removed=[oid for e, oid in seen.events if e is ObstacleEvent.REMOVED])


def referee_status_msg(header: Header, judgement: Judgement) -> RefereeStatus:
    """The referee's judgement of the step of ``header`` (the true odometry's)."""
    return RefereeStatus(
        header=header, min_clearance=judgement.clearance, nearest_obstacle=judgement.nearest,
        collision=judgement.collision, out_of_bounds=judgement.out_of_bounds,
        bounds_clearance=judgement.bounds_clearance)


def plant_contact_msg(ns: int, obstacles: tuple[str, ...], contact_steps: int) -> PlantContact:
    """The step ending at ``ns`` touched ``obstacles`` (physics plant)."""
    msg = PlantContact(obstacles=list(obstacles), contact_steps=int(contact_steps))
    msg.header.stamp = time_msg(ns)
    msg.header.frame_id = MAP_FRAME
    return msg
