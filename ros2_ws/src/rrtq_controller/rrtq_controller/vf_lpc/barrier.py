"""Exponential barrier on the nearest augmented obstacles (VF-LPC eq. 23), vectorised.

``b(p) = beta * sum_i exp(-eta (d_i(p) - d_0))``: ``d_i`` the signed distance from the
position p to obstacle i, ``d_0`` the offset at which one obstacle costs ``beta``. The
paper switches the barrier on by a pursuit-evasion test for moving obstacles (eq. 24,
after Exarchos et al.); our obstacles do not move (a pursuer of speed 0 never catches
the evader outside its own boundary), so the barrier is always on for the ``K`` obstacles
nearest the robot, and its exponential makes far ones cost nothing.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = ['EdgeSet', 'barrier_terms']

# exp() argument cap: keeps a barrier evaluated deep inside an obstacle finite.
_EXP_CAP = 30.0


class EdgeSet:
    """The edges of a few polygons, stacked, for distances from many points at once."""

    def __init__(self, polygons: Sequence[np.ndarray]) -> None:
        polys = [np.asarray(p, dtype=float).reshape(-1, 2) for p in polygons]
        self.count = len(polys)
        sizes = [len(p) for p in polys]
        self._starts = np.r_[0, np.cumsum(sizes)[:-1]].astype(np.intp) if polys else \
            np.zeros(0, np.intp)
        self._ends = self._starts + np.asarray(sizes, dtype=np.intp)
        self._a = np.concatenate(polys) if polys else np.zeros((0, 2))
        self._ab = np.concatenate([np.roll(p, -1, axis=0) - p for p in polys]) if polys \
            else np.zeros((0, 2))
        self._len2 = np.maximum(np.einsum('ij,ij->i', self._ab, self._ab), 1e-300)
        # Edge indices per polygon, (K, E_max), padded with the polygon's first edge (the
        # mask leaves the padding out of the crossing count): one argmin for all polygons.
        sizes = self._ends - self._starts
        k = np.arange(int(sizes.max()) if polys else 0)
        self._mask = k[None, :] < sizes[:, None]
        self._pad = np.where(self._mask, self._starts[:, None] + k[None, :],
                             self._starts[:, None])

    def signed(self, points: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances (N, K) and unit gradients (N, K, 2), K polygons.

        Positive outside, minus the depth inside; the gradient points out of the polygon.
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        a, ab = self._a, self._ab
        px, py = p[:, 0:1], p[:, 1:2]
        apx, apy = px - a[:, 0], py - a[:, 1]                        # (N, E)
        s = (apx * ab[:, 0] + apy * ab[:, 1]) / self._len2
        np.clip(s, 0.0, 1.0, out=s)
        dx, dy = apx - s * ab[:, 0], apy - s * ab[:, 1]
        d2 = dx * dx + dy * dy
        ay, by = a[:, 1], a[:, 1] + ab[:, 1]
        cross = ab[:, 0] * apy - ab[:, 1] * apx
        left = ((ay > py) != (by > py)) & ((cross > 0.0) == (by > ay))
        crossings = (left[:, self._pad] & self._mask).sum(axis=2)   # (N, K)
        j = np.argmin(d2[:, self._pad], axis=2)
        edge = self._pad[np.arange(self.count)[None, :], j]          # nearest edge, (N, K)
        rows = np.arange(len(p))[:, None]
        dist = np.sqrt(d2[rows, edge])
        inv = 1.0 / np.maximum(dist, 1e-12)
        grad = np.stack((dx[rows, edge] * inv, dy[rows, edge] * inv), axis=-1)
        sign = np.where(crossings % 2 == 1, -1.0, 1.0)
        return sign * dist, grad * sign[..., None]


def barrier_terms(points: npt.ArrayLike, edges: EdgeSet, weight: float, rate: float,
                  offset: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Barrier value (N,), gradient (N, 2) and Gauss-Newton Hessian (N, 2, 2) in position.

    The Hessian keeps ``beta eta² e grad(d) grad(d)ᵀ`` and drops the curvature of d
    (positive semi-definite, so the Newton step stays a descent step).
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    if edges.count == 0:
        return np.zeros(len(p)), np.zeros((len(p), 2)), np.zeros((len(p), 2, 2))
    d, g = edges.signed(p)
    e = weight * np.exp(np.minimum(-rate * (d - offset), _EXP_CAP))     # (N, K)
    value = e.sum(axis=1)
    grad = -np.einsum('nk,nkj->nj', rate * e, g)
    hess = np.einsum('nk,nki,nkj->nij', rate * rate * e, g, g)
    return value, grad, hess
