"""A recorded run on the controller's step grid, for the leg table (no rclpy).

:func:`align_steps` joins ``/controller/state``, ``/odom`` (``/odom/truth`` where recorded),
``/cmd_force`` and ``/disturbance`` by stamp, one row per answered step (:class:`Steps`):
the true state, the odometry's noise, the force the plant applied over the step (the
command ``plant.actuation_delay`` steps before, saturated), the disturbance and the legs'
bookkeeping. :mod:`rrtq_bringup.leg_table` computes the legs' costs on it.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rrtq_bringup.scenario import Scenario
from rrtq_sim.simulation import delay_steps

__all__ = ['Steps', 'align_steps']

Array = NDArray[np.float64]


def _keys(t: Array) -> NDArray[np.int64]:
    """Stamps (s) as integer microseconds, for exact joins of the per-step topics."""
    return np.round(np.asarray(t, dtype=float) * 1e6).astype(np.int64)


def _lookup(keys: NDArray[np.int64], table_t: Array) -> NDArray[np.int64]:
    """Index into a series with stamps ``table_t`` for each key (-1 where absent)."""
    tk = _keys(table_t)
    order = np.argsort(tk, kind='stable')
    pos = np.searchsorted(tk[order], keys)
    pos = np.clip(pos, 0, max(tk.size - 1, 0))
    if tk.size == 0:
        return np.full(keys.size, -1, dtype=np.int64)
    found = tk[order][pos] == keys
    return np.where(found, order[pos], -1)


@dataclasses.dataclass(frozen=True)
class Steps:
    """The run on the controller's step grid: t_k, x_k, applied u_k, d_k, leg bookkeeping."""

    t: Array
    x: Array
    """The true state (/odom/truth when recorded, else /odom)."""
    noise: Array
    """What the odometry added to it: /odom - /odom/truth (zero without /odom/truth)."""
    u: Array
    """The force the plant applied over the step: the command ``delay`` steps before,
    saturated (zero before the first)."""
    d: Array
    leg: NDArray[np.int64]
    target: Array
    d0: Array
    actor_w: list[Array]
    tail: tuple[float, Array] | None
    """The odometry sample after the last answered step (time, true state), if recorded."""
    commanded: Array
    """The command of each step, saturated (what enters the actuator's delay line)."""
    delay: int
    """Steps between a command and the step it acts over (``plant.actuation_delay``)."""


def align_steps(data: Any, sc: Scenario) -> Steps:
    """Join /controller/state, /odom(/truth), /cmd_force, /disturbance by stamp (one row per step)."""
    q = sc.disturbance.q
    true_t, true_x = data.true_state() if hasattr(data, 'true_state') else (data.odom_t,
                                                                               data.odom_x)
    state_t = np.asarray(data.state_t, dtype=float)
    order = np.argsort(state_t, kind='stable')
    skeys = _keys(state_t[order])
    oi, ci = _lookup(skeys, true_t), _lookup(skeys, data.cmd_t)
    mi = _lookup(skeys, data.odom_t)
    ok = (oi >= 0) & (ci >= 0) & (mi >= 0)
    order, oi, ci, mi, skeys = order[ok], oi[ok], ci[ok], mi[ok], skeys[ok]
    _, first = np.unique(skeys, return_index=True)    # a resent step is answered twice
    order, oi, ci, mi = order[first], oi[first], ci[first], mi[first]
    t = state_t[order]
    limit = sc.plant.force_limit
    commanded = np.clip(np.asarray(data.cmd_u, dtype=float)[ci], -limit, limit)
    delay = delay_steps(sc.plant.actuation_delay, sc.controller.dt)
    u = np.vstack([np.zeros((min(delay, len(t)), commanded.shape[1])),
                   commanded[:max(len(t) - delay, 0)]])
    x = np.asarray(true_x, dtype=float)[oi]
    d = np.zeros((t.size, q))
    if q and np.asarray(data.dist_t).size:
        di = _lookup(_keys(t), data.dist_t)
        dist = np.asarray(data.dist_d, dtype=float).reshape(-1, q)
        d = np.where(di[:, None] >= 0, dist[np.maximum(di, 0)], 0.0)
    odom_t = np.asarray(true_t, dtype=float)
    after = odom_t > (t[-1] + 1e-7) if t.size else np.zeros(0, dtype=bool)
    tail = (float(odom_t[after][0]), np.asarray(true_x)[after][0]) if after.any() else None
    return Steps(t=t, x=x, noise=np.asarray(data.odom_x, dtype=float)[mi] - x, u=u, d=d,
                  commanded=commanded, delay=delay,
                  leg=np.asarray(data.leg_index)[order],
                  target=np.asarray(data.leg_target, dtype=float).reshape(-1, 2)[order],
                  d0=np.asarray(data.d0, dtype=float)[order],
                  actor_w=[data.actor_w[i] for i in order], tail=tail)
