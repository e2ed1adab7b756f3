"""The kinodynamic composite guiding vector field (VF-LPC eqs. 1, 13-16).

Notation (VF-LPC §III-A after Yao et al., "Guiding vector fields for following occluded
paths", TAC 2022). ``E`` rotates by +90 degrees. The desired path is ``phi = 0``
(:class:`FilletedPath`); obstacle ``i`` has signed distance ``d_i`` to its augmented
polygon, reactive boundary ``R_i = {d_i = w_r}`` and repulsive boundary
``Q_i = {d_i = w_q}`` (``w_q < w_r``).

- path field ``chi_P = -E grad(phi) - k_p phi grad(phi)`` (unit tangent plus pull onto P);
- obstacle field ``chi_Ri = s_i E grad(d_i) - k_r (d_i - w_r) grad(d_i)``: circulates in
  the direction ``s_i`` and pushes out to ``R_i``, so it never lets a curve cross ``Q_i``;
- bump functions of ``sigma = (d_i - w_q)/(w_r - w_q)``: ``f_out = exp(-l/sigma)`` (0 on
  and inside Q), ``f_in = exp(-l/(1-sigma))`` (0 on and outside R); weights
  ``b_Pi = f_out/(f_out+f_in)`` and ``b_Ri = 1 - b_Pi``;
- eq. (1): ``chi = prod_i b_Pi chi_P^ + sum_i b_Ri chi_Ri^`` (hats: unit vectors);
- eq. (13): a virtual obstacle j (a disc of radius ``r_min = v_d²/a_max`` tangent to the
  path before an occluding obstacle, its parent) has ``chi_Vj``, which converges to its
  circle, so a curve it captures turns with curvature ``1/r_min``;
- eq. (16): ``g_j = 1 - exp(-k_v (d_i - w_r))`` outside the parent's reactive boundary,
  0 inside. In the virtual region the curve follows ``g_j chi_Vj^ + (1 - g_j) chi_Ri^``
  with weight ``b_Vj = max(bump(gap/w_r), 1 - g_j)`` (the path weight times
  ``1 - b_Vj``): the virtual field hands the curve to the parent's field, which outside
  ``R_i`` draws it onto ``R_i``, and near ``R_i`` the weight stays up so the path field
  cannot take the turn back. A virtual obstacle acts from the path's tangent point on;
  once the curve is near ``R_i`` (``g_j <= 0.2``) it is switched off for good (Remark 3)
  where the path field stops pointing into the parent, i.e. is tangent to the level set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .config import GuidanceConfig
from .obstacles import PolygonDistances
from .path import FilletedPath, PathQuery

__all__ = ['VirtualObstacle', 'RolloutState', 'CompositeField', 'bump_weights',
           'place_virtual_obstacles']


def _rot(v: np.ndarray) -> np.ndarray:
    """E v (rotation by +90 degrees), on the last axis."""
    return np.stack((-v[..., 1], v[..., 0]), axis=-1)


def bump_weights(sigma: np.ndarray, rate: float) -> np.ndarray:
    """Obstacle weight b_R(sigma): 1 for sigma <= 0 (inside Q), 0 for sigma >= 1 (outside R).

    ``b_R = f_in / (f_in + f_out)`` with the smooth zero-in/zero-out bumps
    ``f_out = exp(-l/sigma)``, ``f_in = exp(-l/(1 - sigma))``: C-infinity, monotone.
    """
    s = np.clip(np.asarray(sigma, dtype=float), 0.0, 1.0)
    with np.errstate(divide='ignore', over='ignore'):
        f_out = np.where(s > 0.0, np.exp(-rate / np.maximum(s, 1e-300)), 0.0)
        f_in = np.where(s < 1.0, np.exp(-rate / np.maximum(1.0 - s, 1e-300)), 0.0)
    return f_in / (f_in + f_out)


@dataclass(frozen=True)
class VirtualObstacle:
    """A virtual obstacle (eq. 13): a disc whose boundary the curve is attracted to.

    Attributes
    ----------
    centre : numpy.ndarray
        (2,), m.
    radius : float
        m: its repulsive circle; ``r_min`` so that following it respects a_max at v_d.
    direction : float
        +1 counter-clockwise, -1 clockwise: the sense the curve goes round it.
    parent : int
        Index of the real obstacle it prepares the turn for.
    start : float
        Arclength (m) of the path's tangent point: the disc acts once the curve's
        progress along the path has reached it, so the curve meets the circle tangentially.
    """

    centre: np.ndarray
    radius: float
    direction: float
    parent: int
    start: float


@dataclass
class RolloutState:
    """What the discrete-time field remembers along one integral curve."""

    progress: float = 0.0                                   # m along the desired path
    direction: np.ndarray | None = None                     # last unit step
    circulation: dict[int, float] = field(default_factory=dict)   # s_i, fixed when met
    entered: set[int] = field(default_factory=set)          # virtual obstacles handed over
    released: set[int] = field(default_factory=set)         # ... and then switched off
    reversed: set[int] = field(default_factory=set)         # s_i flipped at a sink (once)


class CompositeField:
    """Evaluate the composite field (eqs. 1 and 13) at a point.

    Parameters
    ----------
    path : FilletedPath
        The desired path.
    obstacles : PolygonDistances
        The augmented obstacles.
    config : GuidanceConfig
    virtual : list of VirtualObstacle
        From :func:`place_virtual_obstacles`.
    circulation : dict, optional
        Preset directions ``s_i`` (the side an occluding obstacle is passed on).
    """

    # The path is searched this far behind and ahead of the curve's progress, m.
    WINDOW_BACK = 2.0
    WINDOW_AHEAD = 15.0
    # g_j below which the curve counts as handed over to the virtual obstacle's parent.
    HANDOVER = 0.2

    def __init__(self, path: FilletedPath, obstacles: PolygonDistances,
                 config: GuidanceConfig, virtual: list[VirtualObstacle] | None = None,
                 circulation: dict[int, float] | None = None) -> None:
        self.path = path
        self.obstacles = obstacles
        self.config = config
        self.virtual = list(virtual or [])
        self.preset = dict(circulation or {})

    def path_vector(self, xi: np.ndarray, state: RolloutState) -> tuple[np.ndarray, PathQuery]:
        """The unit path field chi_P^ at ``xi`` and the path query it came from."""
        q = self.path.query(xi, state.progress - self.WINDOW_BACK,
                            state.progress + self.WINDOW_AHEAD)
        chi = -_rot(q.grad) - self.config.k_path * q.phi * q.grad
        return chi / np.linalg.norm(chi), q

    def vector(self, xi: np.ndarray, state: RolloutState) -> tuple[np.ndarray, PathQuery]:
        """The composite vector chi(xi) (not normalised) and the path query.

        Sets ``state.circulation`` for obstacles met for the first time, and hands over
        and releases virtual obstacles (Remark 3).
        """
        cfg = self.config
        chi_p, q = self.path_vector(xi, state)
        total = np.zeros(2)
        weight_p = 1.0
        idx = self.obstacles.near(xi, cfg.reactive_width)
        d, grad = np.zeros(0), np.zeros((0, 2))
        if idx.size:
            d, grad = self.obstacles.signed(xi, idx)
            hit = d < cfg.reactive_width
            idx, d, grad = idx[hit], d[hit], grad[hit]
        # Virtual obstacles (eqs. 13, 16): the curve follows the virtual circle, handed
        # over (g) to the parent's field, whose share 1 - g also holds the weight up near
        # R so that the curve goes round R; once near R (g <= HANDOVER), the virtual
        # obstacle is released (Remark 3) where the path field stops pointing into the
        # parent: there chi_P is tangent to R, like the parent's field it replaces.
        for j, v in enumerate(self.virtual):
            if j in state.released or state.progress < v.start:
                continue
            d_p, grad_p = self.obstacles.signed(xi, [v.parent])
            dp, gp = float(d_p[0]), grad_p[0]
            g = 1.0 - math.exp(-cfg.virtual_gain * max(dp - cfg.reactive_width, 0.0))
            if j in state.entered and float(chi_p @ gp) >= 0.0:
                state.released.add(j)
                continue
            rel = xi - v.centre
            rn = max(float(np.hypot(*rel)), 1e-12)
            gap = rn - v.radius
            b_v = float(bump_weights(np.array(gap / cfg.reactive_width), cfg.bump_rate)) \
                if gap > 0.0 else 1.0
            # Near R the parent's share keeps the weight up even where the curve has
            # drifted off the virtual circle: the path field must not take the turn back.
            b_v = max(b_v, 1.0 - g)
            if g <= self.HANDOVER:
                state.entered.add(j)
            n = rel / rn
            chi_v = v.direction * _rot(n) - cfg.k_obstacle * gap * n
            s_p = self._circulation(v.parent, gp, chi_p, state)
            chi_r = s_p * _rot(gp) - cfg.k_obstacle * (dp - cfg.reactive_width) * gp
            total += b_v * (g * chi_v / np.linalg.norm(chi_v)
                            + (1.0 - g) * chi_r / np.linalg.norm(chi_r))
            weight_p *= 1.0 - b_v
        if idx.size:
            s = np.array([self._circulation(int(i), g_i, chi_p, state)
                          for i, g_i in zip(idx, grad)])
            chi_r = s[:, None] * _rot(grad) - cfg.k_obstacle * (
                d - cfg.reactive_width)[:, None] * grad
            chi_r /= np.linalg.norm(chi_r, axis=1, keepdims=True)
            b_r = bump_weights((d - cfg.repulsive_offset)
                               / (cfg.reactive_width - cfg.repulsive_offset), cfg.bump_rate)
            total += b_r @ chi_r
            weight_p *= float(np.prod(1.0 - b_r))
        return total + weight_p * chi_p, q

    def reverse_at_sink(self, xi: np.ndarray, state: RolloutState) -> bool:
        """Flip ``s_i`` of the obstacles whose field the curve is in; True if any was.

        Called when the discrete curve turns back on itself (its step reverses the last
        one): between the two points the composite field has a singular point, where the
        circulation of an obstacle opposes the path field. When it is a sink (the field
        points back at it from both sides, which the eps rule of eq. 17 cannot pass), the
        curve would shuttle there for ever. Each obstacle whose reactive region holds the
        curve, whose sense was chosen along this rollout (not preset for an occluding
        obstacle) and not flipped yet, is given the other sense, once per rollout.
        """
        idx = self.obstacles.near(xi, self.config.reactive_width)
        if not idx.size:
            return False
        d, _ = self.obstacles.signed(xi, idx)
        flipped = False
        for i in (int(k) for k in idx[d < self.config.reactive_width]):
            if i in state.circulation and i not in self.preset and i not in state.reversed:
                state.circulation[i] = -state.circulation[i]
                state.reversed.add(i)
                flipped = True
        return flipped

    def _circulation(self, i: int, grad: np.ndarray, chi_p: np.ndarray,
                     state: RolloutState) -> float:
        """s_i: preset for an occluding obstacle, else the sense closer to chi_P, kept."""
        if i in state.circulation:
            return state.circulation[i]
        if i in self.preset:
            s = self.preset[i]
        else:
            s = 1.0 if float(_rot(grad) @ chi_p) >= 0.0 else -1.0
        state.circulation[i] = s
        return s


def place_virtual_obstacles(path: FilletedPath, obstacles: PolygonDistances,
                            config: GuidanceConfig
                            ) -> tuple[list[VirtualObstacle], dict[int, float]]:
    """One virtual obstacle before each real obstacle that occludes the path (§IV-A1).

    An obstacle occludes the path when the path enters its repulsive boundary Q. Where
    the path first meets its reactive boundary R (arclength ``s_e``), the curve would
    have to turn within ``w_r``. The virtual disc, of radius ``r_min = v_d²/a_max``, is
    tangent to the path at ``s_0 < s_e`` on the side the obstacle is passed on (away
    from its centroid), with ``s_0`` chosen so that the disc's circle touches R
    (Remark 2: the virtual region does not reach the real repulsive region): a curve
    following it turns at curvature ``1/r_min`` and meets R already turned.

    Returns
    -------
    virtual : list of VirtualObstacle
    circulation : dict
        ``s_i`` for each occluding obstacle, consistent with the side chosen.
    """
    cfg = config
    ds = min(cfg.step * 2.0, 0.1)
    # Occlusion is judged on the polyline itself: RRT^X paths touch the augmented
    # obstacles at corners (d = 0), which is not occlusion; crossing an interior is.
    occluding: set[int] = set()
    verts = path.vertices
    for a, b in zip(verts[:-1], verts[1:]):
        n = max(int(math.ceil(float(np.hypot(*(b - a))) / ds)), 1)
        for p in a + (b - a) * (np.arange(n + 1) / n)[:, None]:
            idx = obstacles.near(p, 0.0)
            if idx.size:
                d, _ = obstacles.signed(p, idx)
                occluding.update(int(i) for i in idx[d < -1e-6])
    first_r: dict[int, float] = {}
    if occluding:
        for s, p in zip(np.arange(0.0, path.length + ds, ds),
                        path.point(np.arange(0.0, path.length + ds, ds))):
            close = [i for i in obstacles.near(p, cfg.reactive_width)
                     if int(i) in occluding and int(i) not in first_r]
            if close:
                d, _ = obstacles.signed(p, close)
                first_r.update((int(i), float(s)) for i, di in zip(close, d)
                               if di <= cfg.reactive_width)
    virtual: list[VirtualObstacle] = []
    circulation: dict[int, float] = {}
    r = cfg.min_turn_radius
    for i in sorted(first_r, key=lambda k: first_r[k]):
        s_e = first_r[i]
        p_e = path.point(s_e)
        t_e = -_rot(path.query(p_e).grad)
        to_c = obstacles.centroids[i] - p_e
        left = float(t_e[0] * to_c[1] - t_e[1] * to_c[0]) < 0.0   # centroid on the right
        side = 1.0 if left else -1.0
        circulation[i] = -side           # passed on the left: obstacle on the right, cw

        def centre(s0: float, side: float = side) -> np.ndarray:
            p0 = path.point(s0)
            n = _rot(path.query(p0).grad) * -1.0
            return p0 + side * r * _rot(n)

        def gap(s0: float, i: int = i) -> float:
            return float(obstacles.signed(centre(s0), [i])[0][0]) - (r + cfg.reactive_width)

        lo, hi = max(s_e - 4.0 * r, 0.0), s_e
        if gap(hi) >= 0.0:
            s0 = hi
        elif gap(lo) <= 0.0:
            s0 = lo
        else:
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if gap(mid) > 0.0 else (lo, mid)
            s0 = lo
        virtual.append(VirtualObstacle(centre(s0), r, side, i, s0))
    return virtual, circulation
