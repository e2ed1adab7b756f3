"""The discrete integral curve (VF-LPC eq. 17), its speed profile and the reference trajectory.

- eq. (17): ``xi_{k+1} = xi_k + h chi(xi_k)/|chi(xi_k)|``; a vector shorter than ``eps``
  is not followed but the previous direction is kept, so a singular point of the
  composite field (a deadlock) is passed instead of stopping the curve there.
- speed (§IV-A1): ``v = min(v_d, sqrt(a_max / kappa))`` at every point, with ``kappa``
  the curve's Menger curvature (the largest within three points either side, so that
  samples taken between curve points stay under the bound); then ``|dv/dt| <= a_max`` by a forward
  pass from the robot's speed and a backward pass to rest at the goal (our addition: a
  reference the plant can follow in both directions).
- time: constant acceleration between curve points, sampled at ``dt``.
- connector (our addition): a curve rolled out from a moving robot leaves it along its
  velocity and turns towards the field no faster than curvature
  ``LEAD_FRACTION a_max / |v|²`` (a turn the robot can fly at its speed) until its step is
  the field's; near an obstacle the field takes over at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .config import CurveStatus, GuidanceConfig
from .field import CompositeField, RolloutState

# Points either side whose curvature bounds a point's speed.
KAPPA_REACH = 3
# The connector from a moving robot turns at this share of a_max / |v|² at most.
LEAD_FRACTION = 0.8

__all__ = ['Curve', 'Reference', 'integral_curve', 'menger_curvature', 'speed_profile',
           'sample_in_time']


@dataclass(frozen=True)
class Curve:
    """A rolled-out integral curve: points every ``step`` m and how the rollout ended."""

    points: np.ndarray          # (K, 2) m
    progress: np.ndarray        # (K,) m, arclength of each point's projection on the path
    status: CurveStatus


@dataclass(frozen=True)
class Reference:
    """Positions and velocities at t0 + k dt, k = 0..K-1 (what /guidance/reference carries)."""

    t: np.ndarray               # (K,) s
    positions: np.ndarray       # (K, 2) m
    velocities: np.ndarray      # (K, 2) m/s

    @property
    def states(self) -> np.ndarray:
        """(K, 4): p_x, p_y, v_x, v_y."""
        return np.hstack((self.positions, self.velocities))


def integral_curve(field: CompositeField, start: npt.ArrayLike, length: float,
                   state: RolloutState | None = None,
                   velocity: npt.ArrayLike | None = None) -> Curve:
    """Roll the discrete-time field (eq. 17) out from ``start`` for ``length`` m at most.

    With the robot's ``velocity`` (m/s), the curve is continuous with its motion: the
    first step is along the velocity, and each step turns towards the field's direction
    by at most ``h LEAD_FRACTION a_max / |v|²`` (so the connector's curvature allows the
    robot's speed, v²κ <= a_max) until the field's direction is within that turn; from
    there on, and at once when a point comes within the middle of an obstacle's
    sandwiched region (``(w_q + w_r)/2``), the curve is the field's (eq. 17).

    Stops at the end of the desired path, within half the reactive width of the goal
    (``REACHED``, the goal appended), after
    ``length`` (``LENGTH``), or when the projection on the path has not advanced over
    ``stall_distance`` of curve (``STALLED``).
    """
    cfg = field.config
    h = cfg.step
    st = state or RolloutState(progress=field.path.query(np.asarray(start, float)).s)
    xi = np.array(start, dtype=float).reshape(2)
    pts = [xi.copy()]
    prog = [st.progress]
    best, best_at, travelled = st.progress, 0.0, 0.0
    status = CurveStatus.LENGTH
    goal = field.path.goal
    lead, turn = _connector(velocity, cfg)
    release = 0.5 * (cfg.repulsive_offset + cfg.reactive_width)
    while travelled < length:
        chi, q = field.vector(xi, st)
        norm = float(np.hypot(*chi))
        if st.direction is not None and norm > 0.0 and float(chi @ st.direction) < 0.0 \
                and field.reverse_at_sink(xi, st):
            chi, q = field.vector(xi, st)      # the curve turned back: a sink (field.py)
            norm = float(np.hypot(*chi))
        if norm >= cfg.deadlock_epsilon or st.direction is None:
            direction = chi / norm if norm > 0.0 else -np.array([-q.grad[1], q.grad[0]])
        else:
            direction = st.direction
        if lead is not None:
            # The connector's step, then its turn towards the field for the next one.
            near = field.obstacles.near(xi, release)
            if near.size and float(field.obstacles.signed(xi, near)[0].min()) < release:
                lead = None
            else:
                angle = math.atan2(lead[0] * direction[1] - lead[1] * direction[0],
                                   float(lead @ direction))
                if abs(angle) <= turn and len(pts) > 1:
                    lead = None          # aligned: the field's from here on
                else:
                    a = math.copysign(min(turn, abs(angle)), angle)
                    c, s = math.cos(a), math.sin(a)
                    direction, lead = lead, np.array([c * lead[0] - s * lead[1],
                                                      s * lead[0] + c * lead[1]])
        st.direction = direction
        st.progress = max(q.s, st.progress - field.WINDOW_BACK / 2.0)
        to_goal = float(np.hypot(*(xi - goal)))
        if q.s >= field.path.length - 0.5 * h and to_goal <= 0.5 * cfg.reactive_width:
            if to_goal > 1e-9:
                pts.append(goal.copy())
                prog.append(field.path.length)
            status = CurveStatus.REACHED
            break
        xi = xi + h * direction
        travelled += h
        pts.append(xi.copy())
        prog.append(q.s)
        # Past the goal on the extended last leg is no progress.
        if min(q.s, field.path.length) > best + 1e-9:
            best, best_at = min(q.s, field.path.length), travelled
        elif travelled - best_at > cfg.stall_distance:
            status = CurveStatus.STALLED
            break
    return Curve(np.array(pts), np.array(prog), status)


def _connector(velocity: npt.ArrayLike | None, cfg: GuidanceConfig
               ) -> tuple[np.ndarray | None, float]:
    """The connector's start direction (None: at rest) and largest turn per step, rad."""
    if velocity is None:
        return None, math.pi
    v = np.asarray(velocity, dtype=float).reshape(2)
    speed = float(np.hypot(*v))
    if speed <= 1e-9:
        return None, math.pi
    turn = cfg.step * LEAD_FRACTION * cfg.a_max / speed ** 2
    return (v / speed, turn) if turn < math.pi else (None, math.pi)


def menger_curvature(points: np.ndarray) -> np.ndarray:
    """Curvature (1/m) at each interior point of a polyline: 4 area / (a b c); 0 at the ends."""
    p = np.asarray(points, dtype=float)
    out = np.zeros(len(p))
    if len(p) < 3:
        return out
    a = p[1:-1] - p[:-2]
    b = p[2:] - p[1:-1]
    c = p[2:] - p[:-2]
    cross = np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    den = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) * np.linalg.norm(c, axis=1)
    with np.errstate(divide='ignore', invalid='ignore'):
        out[1:-1] = np.where(den > 0.0, 2.0 * cross / den, 0.0)
    return out


def speed_profile(points: np.ndarray, config: GuidanceConfig, v0: float,
                  stop_at_end: bool) -> np.ndarray:
    """Speed (m/s) at each curve point: lateral cap, then forward and backward passes."""
    kappa = menger_curvature(points)
    if len(kappa) > 2:
        # The largest curvature within KAPPA_REACH points either side: a reference
        # sample spans up to v_max dt of curve, more than one step h.
        padded = np.pad(kappa, KAPPA_REACH)
        kappa = np.max(np.lib.stride_tricks.sliding_window_view(
            padded, 2 * KAPPA_REACH + 1), axis=1)
    with np.errstate(divide='ignore'):
        cap = np.minimum(config.v_max, np.sqrt(config.a_max / kappa))
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    v = cap.copy()
    v[0] = min(max(v0, 0.0), cap[0])
    two_a = 2.0 * config.a_max
    for i in range(len(seg)):
        v[i + 1] = min(v[i + 1], math.sqrt(v[i] ** 2 + two_a * seg[i]))
    if stop_at_end:
        v[-1] = 0.0
    for i in range(len(seg) - 1, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + two_a * seg[i]))
    return v


def sample_in_time(points: np.ndarray, speeds: np.ndarray, dt: float, count: int,
                   t0: float = 0.0) -> Reference:
    """``count`` samples every ``dt`` of the curve travelled at ``speeds`` (const. accel.).

    Past the curve's end the last point is held at rest.
    """
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    v0, v1 = speeds[:-1], speeds[1:]
    with np.errstate(divide='ignore', invalid='ignore'):
        dur = np.where(seg > 0.0, 2.0 * seg / (v0 + v1), 0.0)
    dur = np.where(np.isfinite(dur), dur, np.inf)
    t_nodes = np.r_[0.0, np.cumsum(dur)]
    tk = dt * np.arange(count)
    i = np.clip(np.searchsorted(t_nodes, tk, side='right') - 1, 0, max(len(seg) - 1, 0))
    pos = np.empty((count, 2))
    vel = np.zeros((count, 2))
    if len(seg) == 0:
        pos[:] = points[0]
        return Reference(t0 + tk, pos, vel)
    tau = np.minimum(tk - t_nodes[i], np.where(np.isfinite(dur[i]), dur[i], 0.0))
    with np.errstate(divide='ignore', invalid='ignore'):
        acc = np.where(seg[i] > 0.0, (v1[i] ** 2 - v0[i] ** 2) / (2.0 * seg[i]), 0.0)
    s = np.minimum(v0[i] * tau + 0.5 * acc * tau ** 2, seg[i])
    speed = np.maximum(v0[i] + acc * tau, 0.0)
    with np.errstate(divide='ignore', invalid='ignore'):
        unit = np.where(seg[i, None] > 0.0, (points[i + 1] - points[i]) / seg[i, None], 0.0)
    pos[:] = points[i] + s[:, None] * unit
    vel[:] = speed[:, None] * unit
    done = tk >= t_nodes[-1]
    pos[done] = points[-1]
    vel[done] = 0.0
    return Reference(t0 + tk, pos, vel)
