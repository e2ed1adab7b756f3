"""Messages <-> core types of the controller: its state and its command."""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, WrenchStamped
from numpy.typing import ArrayLike
from numpy.typing import NDArray
from rrtq_msgs.msg import ControllerState, GuidanceReference

from rrtq_common.conversions import MAP_FRAME, ROBOT_FRAME, stamp_ns
from rrtq_common.lockstep import OnChange

from .config import ControllerConfig
from .driver import ControlOutput


def _floats(values: ArrayLike) -> list[float]:
    return np.asarray(values, dtype=float).ravel().tolist()


def controller_state_msg(stamp: Time, config: ControllerConfig,
                         out: ControlOutput | None) -> ControllerState:
    """/controller/state of one step (``out`` None: the step was refused, zero force)."""
    u = out.u if out is not None else np.zeros(2)
    state = ControllerState(variant=str(config.variant), command=_floats(u),
                            force_limit=float(config.force_limit))
    if out is not None:
        state.leg_index = out.leg_index
        state.leg_start_time, state.horizon = out.leg_start_time, config.horizon
        state.time_to_go = out.time_to_go
        state.leg_start = Point(x=float(out.leg_start[0]), y=float(out.leg_start[1]))
        state.leg_target = Point(x=float(out.leg_target[0]), y=float(out.leg_target[1]))
        state.d0, state.d, state.rho = out.d0, out.d, config.rho
        state.probing_noise = _floats(out.probing)
        state.time_rates = _floats(out.time_rates)
        state.time_powers = _floats(out.time_powers)
        state.critic_weights = _floats(out.critic_weights)
        state.actor_weights = _floats(out.actor_weights)
        state.disturbance_weights = _floats(out.disturbance_weights)
        state.critic_error, state.terminal_error = out.critic_error, out.terminal_error
        state.policy_event, state.policy_reason = out.policy_event, out.policy_reason
        state.tracking_error, state.horizon_cost = out.tracking_error, out.horizon_cost
        state.prediction_error = _floats(out.prediction_error)
        state.nominal_error = _floats(out.nominal_error)
        state.prediction_std = _floats(out.prediction_std)
        state.gp_dictionary = out.gp_dictionary
        state.keep_off = float(out.keep_off)
    state.header.stamp = stamp
    state.header.frame_id = MAP_FRAME
    return state


def command_msg(stamp: Time, u: ArrayLike) -> WrenchStamped:
    """/cmd_force: the planar force (N) in ``base_link``."""
    force = np.asarray(u, dtype=float)
    cmd = WrenchStamped()
    cmd.header.stamp = stamp
    cmd.header.frame_id = ROBOT_FRAME
    cmd.wrench.force.x, cmd.wrench.force.y = float(force[0]), float(force[1])
    return cmd


def reference_states(msg: GuidanceReference) -> NDArray[np.float64]:
    """(K, 4) reference states p_x, p_y, v_x, v_y of /guidance/reference."""
    return np.array([[p.x, p.y, v.x, v.y] for p, v in zip(msg.positions, msg.velocities,
                                                          strict=True)],
                    dtype=float).reshape(-1, 4)


def changed_reference(msg: GuidanceReference | None
                      ) -> OnChange[tuple[NDArray[np.float64], int]] | None:
    """This step's reference as an input: its stamp; its states and rollout read on demand."""
    if msg is None:
        return None
    return OnChange(stamp_ns(msg.header.stamp), lambda: (reference_states(msg), msg.rollout))
