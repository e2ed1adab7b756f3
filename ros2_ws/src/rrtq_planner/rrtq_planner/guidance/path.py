"""The desired path as a level set: a polyline with filleted corners and its signed distance.

VF-LPC §III-A asks for a desired path ``P = {xi : phi(xi) = 0}`` with ``phi`` twice
continuously differentiable; the RRT^X path is a polyline. Each corner is replaced by the
circular arc of radius ``min(r_min, r_fit)`` tangent to both legs (``r_min = v_d²/a_max``,
``r_fit`` what the legs' lengths allow), which makes the path C¹ with curvature at most
``1/r``; ``phi`` is the signed distance to it (left of the direction of travel positive),
exact and smooth in a tube around the path narrower than the fillet radii. The first and
last legs are extended as rays so that the field is defined before the start and past the
goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ['PathQuery', 'FilletedPath']

_TINY = 1e-12


def _left(v: np.ndarray) -> np.ndarray:
    """E v: the vector rotated by +90 degrees (E = [[0, -1], [1, 0]])."""
    return np.stack((-v[..., 1], v[..., 0]), axis=-1)


@dataclass(frozen=True)
class PathQuery:
    """phi, its gradient and the arclength of the nearest path point, at one point."""

    phi: float              # m, signed distance (left positive)
    grad: np.ndarray        # (2,) unit gradient of phi
    s: float                # m, arclength of the nearest point (may be < 0 or > length)


class FilletedPath:
    """A polyline path rounded at its corners.

    Parameters
    ----------
    vertices : array_like, shape (k, 2)
        The polyline, m (start first, goal last; k >= 2, consecutive duplicates dropped).
    radius : float
        Largest fillet radius, m (> 0): ``v_d² / a_max`` keeps the path within the
        acceleration limit at the desired speed.
    """

    def __init__(self, vertices: npt.ArrayLike, radius: float) -> None:
        pts = np.asarray(vertices, dtype=float).reshape(-1, 2)
        keep = np.r_[True, np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9]
        pts = pts[keep]
        if len(pts) < 2:
            raise ValueError('a path needs two distinct vertices')
        if not radius > 0.0:
            raise ValueError(f'radius must be > 0, got {radius!r}')
        self.vertices = pts
        d = np.diff(pts, axis=0)
        length = np.linalg.norm(d, axis=1)
        u = d / length[:, None]
        k = len(length)
        # Tangent length available at each corner: half a shared leg, all of an end leg.
        share = np.full(k, 0.5)
        share[0] = share[-1] = 1.0
        cut_in = np.zeros(k)     # leg i shortened at its start by the fillet at vertex i
        cut_out = np.zeros(k)    # ... and at its end by the fillet at vertex i + 1
        arcs = []                # (leg index before it, centre, radius, theta0, sweep)
        for i in range(1, k):
            cross = u[i - 1, 0] * u[i, 1] - u[i - 1, 1] * u[i, 0]
            turn = math.atan2(cross, float(u[i - 1] @ u[i]))
            if abs(turn) < 1e-6:
                continue
            half = math.tan(abs(turn) / 2.0)
            room = min(length[i - 1] * share[i - 1], length[i] * share[i])
            r = min(radius, room / half)
            t = r * half
            cut_out[i - 1], cut_in[i] = t, t
            a = pts[i] - t * u[i - 1]
            side = 1.0 if turn > 0 else -1.0
            centre = a + side * r * _left(u[i - 1])
            theta0 = math.atan2(a[1] - centre[1], a[0] - centre[0])
            arcs.append((i - 1, centre, r, theta0, turn))
        seg_a = pts[:-1] + cut_in[:, None] * u
        seg_b = pts[1:] - cut_out[:, None] * u
        seg_len = np.maximum(length - cut_in - cut_out, 0.0)
        # Arclength along the rounded path: leg, arc, leg, arc, ...
        arc_after = {leg: (c, r, th, sw) for leg, c, r, th, sw in arcs}
        seg_s0 = np.zeros(k)
        arc_rows = []
        s = 0.0
        for i in range(k):
            seg_s0[i] = s
            s += seg_len[i]
            if i in arc_after:
                c, r, th, sw = arc_after[i]
                arc_rows.append((c[0], c[1], r, th, sw, s))
                s += r * abs(sw)
        self.length = s
        self._seg_a, self._seg_b = seg_a, seg_b
        self._seg_u, self._seg_len, self._seg_s0 = u, seg_len, seg_s0
        arr = np.array(arc_rows, dtype=float).reshape(-1, 6)
        self._arc_c, self._arc_r = arr[:, :2], arr[:, 2]
        self._arc_th, self._arc_sw, self._arc_s0 = arr[:, 3], arr[:, 4], arr[:, 5]
        self._arc_turn = np.sign(self._arc_sw)
        self._arc_span = np.abs(self._arc_sw)
        self._arc_end = self._arc_s0 + self._arc_r * self._arc_span
        self._seg_end = seg_s0 + seg_len
        self._seg_lo = np.zeros(k)
        self._seg_lo[0] = -math.inf

    @property
    def goal(self) -> np.ndarray:
        """The last vertex, m."""
        return self.vertices[-1]

    @property
    def fillet_radii(self) -> np.ndarray:
        """Radius of each corner's arc, m."""
        return self._arc_r.copy()

    def point(self, s: npt.ArrayLike) -> np.ndarray:
        """Points (..., 2) at arclengths ``s`` (clipped to [0, length])."""
        ss = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        flat = ss.reshape(-1)
        out = np.empty((flat.size, 2))
        seg = np.clip(np.searchsorted(self._seg_s0, flat, side='right') - 1, 0, None)
        along = flat - self._seg_s0[seg]
        on_seg = along <= self._seg_len[seg] + 1e-12
        out[:] = self._seg_a[seg] + np.minimum(along, self._seg_len[seg])[:, None] \
            * self._seg_u[seg]
        if len(self._arc_s0) and not on_seg.all():
            j = np.clip(np.searchsorted(self._arc_s0, flat[~on_seg], side='right') - 1, 0, None)
            ang = self._arc_th[j] + np.sign(self._arc_sw[j]) * (
                flat[~on_seg] - self._arc_s0[j]) / self._arc_r[j]
            out[~on_seg] = self._arc_c[j] + self._arc_r[j][:, None] * np.column_stack(
                (np.cos(ang), np.sin(ang)))
        return out.reshape(ss.shape + (2,))

    def query(self, xi: np.ndarray, s_lo: float = -math.inf,
              s_hi: float = math.inf) -> PathQuery:
        """phi, grad phi and the nearest arclength at ``xi``, searching pieces in [s_lo, s_hi].

        The window keeps a rollout on the part of the path it is following: a path that
        folds back on itself would otherwise hand the curve to an earlier or much later
        piece (phi is the distance to the windowed path).
        """
        p = np.asarray(xi, dtype=float)
        ns = len(self._seg_len)
        i0 = max(int(np.searchsorted(self._seg_end, s_lo, side='left')), 0)
        i1 = min(int(np.searchsorted(self._seg_s0, s_hi, side='right')), ns)
        if i1 <= i0:
            i0, i1 = (ns - 1, ns) if s_lo > self.length else (0, 1)
        a, u, ln = self._seg_a[i0:i1], self._seg_u[i0:i1], self._seg_len[i0:i1]
        rel = p - a
        t = rel[:, 0] * u[:, 0] + rel[:, 1] * u[:, 1]
        # The first and last legs extend as rays.
        tc = np.minimum(np.maximum(t, self._seg_lo[i0:i1]), np.where(
            np.arange(i0, i1) == ns - 1, math.inf, ln))
        diff = rel - tc[:, None] * u
        d2 = diff[:, 0] ** 2 + diff[:, 1] ** 2
        k = int(np.argmin(d2))
        best = math.sqrt(float(d2[k]))
        uk = u[k]
        if best > _TINY:
            side = 1.0 if uk[0] * rel[k, 1] - uk[1] * rel[k, 0] >= 0.0 else -1.0
            grad = side * diff[k] / best
        else:
            side, grad = 1.0, np.array([-uk[1], uk[0]])
        phi, s_best = side * best, float(self._seg_s0[i0 + k] + tc[k])
        na = len(self._arc_r)
        if na:
            j0 = int(np.searchsorted(self._arc_end, s_lo, side='left'))
            j1 = int(np.searchsorted(self._arc_s0, s_hi, side='right'))
            if j1 > j0:
                c, r = self._arc_c[j0:j1], self._arc_r[j0:j1]
                rc = p - c
                rn = np.sqrt(rc[:, 0] ** 2 + rc[:, 1] ** 2)
                turn = self._arc_turn[j0:j1]
                delta = np.mod(turn * (np.arctan2(rc[:, 1], rc[:, 0]) - self._arc_th[j0:j1]),
                               2.0 * math.pi)
                ad = np.where(delta <= self._arc_span[j0:j1], np.abs(rn - r), math.inf)
                j = int(np.argmin(ad))
                if ad[j] < best and rn[j] > _TINY:
                    # Centre on the left of a left turn: inside the circle is the left side.
                    phi = float(turn[j] * (r[j] - rn[j]))
                    grad = -turn[j] * rc[j] / rn[j]
                    s_best = float(self._arc_s0[j0 + j] + r[j] * delta[j])
        return PathQuery(phi, grad, s_best)
