"""Signed distance and its gradient to the polygons near one point, vectorised over edges.

The fields of the guiding level need, at every step of the integral curve, the distance
``d_i`` from the curve's point to each augmented obstacle within reach and the unit
gradient ``grad d_i`` (away from the obstacle). Bounding boxes give a lower bound on every
distance, so only the polygons whose box lies within the query radius get the exact test.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = ['PolygonDistances']


class PolygonDistances:
    """Polygons (each ``(k, 2)``, m, either orientation, no repeated closing vertex).

    Parameters
    ----------
    polygons : sequence of array_like
        The obstacles; their position in this sequence is their index in every answer.
    """

    def __init__(self, polygons: Sequence[npt.ArrayLike]) -> None:
        polys = [np.asarray(p, dtype=float).reshape(-1, 2) for p in polygons]
        if any(len(p) < 3 for p in polys):
            raise ValueError('every polygon needs at least 3 vertices')
        self.polygons = polys
        self.count = len(polys)
        sizes = np.array([len(p) for p in polys], dtype=np.intp)
        self._a = np.concatenate(polys) if polys else np.zeros((0, 2))
        self._b = (np.concatenate([np.roll(p, -1, axis=0) for p in polys]) if polys
                   else np.zeros((0, 2)))
        self._ab = self._b - self._a
        self._len2 = np.maximum(np.einsum('ij,ij->i', self._ab, self._ab), 1e-300)
        self._first = np.r_[0, np.cumsum(sizes)[:-1]].astype(np.intp)
        self._sizes = sizes
        self._lo = np.array([p.min(axis=0) for p in polys]).reshape(-1, 2)
        self._hi = np.array([p.max(axis=0) for p in polys]).reshape(-1, 2)
        self.centroids = np.array([p.mean(axis=0) for p in polys]).reshape(-1, 2)

    def near(self, point: npt.ArrayLike, radius: float) -> np.ndarray:
        """Indices of the polygons whose bounding box is within ``radius`` of ``point``."""
        if self.count == 0:
            return np.zeros(0, dtype=np.intp)
        p = np.asarray(point, dtype=float).reshape(2)
        gap = np.maximum(np.maximum(self._lo - p, p - self._hi), 0.0)
        return np.flatnonzero(gap[:, 0] ** 2 + gap[:, 1] ** 2 <= radius * radius)

    def signed(self, point: npt.ArrayLike, indices: npt.ArrayLike
               ) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (m) and unit gradient of each polygon of ``indices`` at ``point``.

        Returns
        -------
        d : numpy.ndarray, shape (k,)
            Positive outside, minus the depth inside.
        grad : numpy.ndarray, shape (k, 2)
            ``grad d``: from the nearest boundary point towards ``point`` outside, away
            from it inside (both point out of the obstacle).
        """
        p = np.asarray(point, dtype=float).reshape(2)
        idx = np.asarray(indices, dtype=np.intp).reshape(-1)
        if idx.size == 0:
            return np.zeros(0), np.zeros((0, 2))
        d = np.empty(idx.size)
        grad = np.empty((idx.size, 2))
        for k, i in enumerate(idx):      # few polygons per query: one vector op set each
            d[k], grad[k] = self._signed_one(p, int(i))
        return d, grad

    def _signed_one(self, p: np.ndarray, i: int) -> tuple[float, np.ndarray]:
        lo = self._first[i]
        a = self._a[lo:lo + self._sizes[i]]
        ab = self._ab[lo:lo + self._sizes[i]]
        len2 = self._len2[lo:lo + self._sizes[i]]
        ap = p - a
        s = (ap[:, 0] * ab[:, 0] + ap[:, 1] * ab[:, 1]) / len2
        np.clip(s, 0.0, 1.0, out=s)
        diff = ap - s[:, None] * ab
        d2 = diff[:, 0] ** 2 + diff[:, 1] ** 2
        j = int(np.argmin(d2))
        dist = math.sqrt(float(d2[j]))
        # Crossing number of a ray to +x, without division (as PolygonSet).
        ay = a[:, 1]
        by = ay + ab[:, 1]
        cross = ab[:, 0] * ap[:, 1] - ab[:, 1] * ap[:, 0]
        inside = int(np.count_nonzero(((ay > p[1]) != (by > p[1]))
                                      & ((cross > 0.0) == (by > ay)))) % 2 == 1
        sign = -1.0 if inside else 1.0
        if dist > 1e-12:
            g = diff[j] / dist
        else:                   # on the boundary: the edge's normal, away from the centroid
            e = ab[j]
            g = np.array([e[1], -e[0]]) / math.hypot(e[0], e[1])
            if float(g @ (a[j] - self.centroids[i])) < 0.0:
                g = -g
            sign = 1.0
        return sign * dist, sign * g
