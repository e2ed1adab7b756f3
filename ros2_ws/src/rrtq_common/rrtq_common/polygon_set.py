"""A fixed set of polygons queried from one point: the nearest, and those meeting a disc.

The referee, the safety node and the spawner ask at every step how far the robot is from
the nearest true obstacle, or which obstacles meet the perception disc, and a forest has
hundreds of them. Each polygon's bounding box gives a lower bound on its distance, so
only the few polygons that can matter get the exact test, all at once over their
stacked edges. Distances are signed: inside a polygon the distance is minus the depth
(the distance to its boundary), so a robot of radius 0 inside an obstacle is still
below zero clearance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ['LivePolygons', 'PolygonSet']


class PolygonSet:
    """Polygons (each ``(k, 2)``, m, either orientation, no repeated closing vertex).

    Parameters
    ----------
    polygons : sequence of array_like
        The polygons; their index in this sequence names them in every answer.
    """

    SMALL = 16
    """Up to this many polygons, :meth:`nearest` and :meth:`within` test every one."""

    def __init__(self, polygons: Sequence[npt.ArrayLike]) -> None:
        polys = [np.asarray(p, dtype=float).reshape(-1, 2) for p in polygons]
        self._count = len(polys)
        sizes = np.array([len(p) for p in polys], dtype=np.intp)
        if np.any(sizes < 3):
            raise ValueError('every polygon needs at least 3 vertices')
        self._a = np.concatenate(polys) if polys else np.zeros((0, 2))
        self._b = (np.concatenate([np.roll(p, -1, axis=0) for p in polys]) if polys
                   else np.zeros((0, 2)))
        self._owner = np.repeat(np.arange(self._count), sizes)
        self._lo = np.array([p.min(axis=0) for p in polys]).reshape(-1, 2)
        self._hi = np.array([p.max(axis=0) for p in polys]).reshape(-1, 2)
        # What does not depend on the query point, once per set (per edge, elementwise:
        # the same values as computed for any subset of the edges).
        self._ab = self._b - self._a
        self._len2 = np.einsum('ij,ij->i', self._ab, self._ab)
        self._starts = np.concatenate(([0], np.cumsum(sizes)[:-1])).astype(np.intp)
        self._all = np.arange(self._count)

    def __len__(self) -> int:
        return self._count

    def box_distances(self, point: npt.ArrayLike) -> np.ndarray:
        """(n,) distance (m) from ``point`` to each bounding box: a lower bound, 0 inside."""
        p = np.asarray(point, dtype=float).reshape(2)
        gap = np.maximum(np.maximum(self._lo - p, p - self._hi), 0.0)
        return np.hypot(gap[:, 0], gap[:, 1])

    def signed_distances(self, point: npt.ArrayLike, indices: npt.ArrayLike) -> np.ndarray:
        """Signed distance (m) from ``point`` to each polygon of ``indices`` (unique).

        Positive outside, 0 on the boundary, minus the distance to the boundary inside.
        """
        p = np.asarray(point, dtype=float).reshape(2)
        idx = np.asarray(indices, dtype=np.intp).reshape(-1)
        if idx.size == 0:
            return np.zeros(0)
        if idx.size == self._count and np.array_equal(idx, self._all):
            return self._signed(p, slice(None), self._starts)  # every polygon, in order
        chosen = np.zeros(self._count, dtype=bool)
        chosen[idx] = True
        e = np.flatnonzero(chosen[self._owner])     # edges, grouped by ascending owner
        owner = self._owner[e]
        starts = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
        signed = self._signed(p, e, starts)
        return signed[np.searchsorted(owner[starts], idx)]

    def _signed(self, p: np.ndarray, e: npt.NDArray[np.intp] | slice,
                starts: np.ndarray) -> np.ndarray:
        """Signed distances to the polygons whose edges ``e`` begin at ``starts`` in ``e``."""
        a, ab, len2 = self._a[e], self._ab[e], self._len2[e]
        ap = p - a
        with np.errstate(divide='ignore', invalid='ignore'):
            s = np.where(len2 > 0.0, np.einsum('ij,ij->i', ap, ab) / len2, 0.0)
        diff = ap - np.clip(s, 0.0, 1.0)[:, None] * ab
        d2 = np.einsum('ij,ij->i', diff, diff)
        dist = np.sqrt(np.minimum.reduceat(d2, starts))
        # Crossing number of a ray to +x, without division (as ObstacleMap.point_free).
        ay, by = a[:, 1], self._b[e][:, 1]
        cross = ab[:, 0] * ap[:, 1] - ab[:, 1] * ap[:, 0]
        left = ((ay > p[1]) != (by > p[1])) & ((cross > 0.0) == (by > ay))
        inside = np.add.reduceat(left.astype(np.intp), starts) % 2 == 1
        return np.where(inside, -dist, dist)

    def nearest(self, point: npt.ArrayLike) -> tuple[float, int]:
        """Signed distance (m) to the nearest polygon and its index; (inf, -1) if there is none.

        Exact: a polygon is skipped only when its box is farther than a distance already
        found (or, inside a polygon, when its box does not hold the point). On a tie the
        lower index wins.
        """
        if self._count == 0:
            return math.inf, -1
        if self._count <= self.SMALL:
            # Few polygons: the exact distance to all of them costs less than the pruning.
            distances = self.signed_distances(point, self._all)
            j = int(np.argmin(distances))
            return float(distances[j]), j
        lower = self.box_distances(point)
        first = int(np.argmin(lower))
        near = lower <= max(float(self.signed_distances(point, [first])[0]), 0.0)
        near[first] = True          # its box and its distance may differ in the last bit
        candidates = np.flatnonzero(near)
        distances = self.signed_distances(point, candidates)
        j = int(np.argmin(distances))
        return float(distances[j]), int(candidates[j])

    def within(self, point: npt.ArrayLike, radius: float) -> np.ndarray:
        """Indices (ascending) of the polygons that meet the closed disc."""
        if self._count <= self.SMALL:
            return np.flatnonzero(self.signed_distances(point, self._all) <= radius)
        candidates = np.flatnonzero(self.box_distances(point) <= radius)
        return candidates[self.signed_distances(point, candidates) <= radius]

    def cast(self, origin: npt.ArrayLike, direction: npt.ArrayLike,
             length: float) -> tuple[float, int, tuple[float, float]]:
        """The first boundary the ray from ``origin`` along ``direction`` meets within ``length``.

        Returns the distance (m) along the unit ``direction`` to it, the polygon's index and
        the unit normal of the edge hit, on the side the ray came from; (inf, -1, (0, 0)) when
        no edge lies on the ray within ``length``. Only the polygons whose bounding boxes
        meet the box of the ray's segment are tested, their edges all at once.
        """
        p = np.asarray(origin, dtype=float).reshape(2)
        d = np.asarray(direction, dtype=float).reshape(2)
        if self._count == 0 or not float(d @ d) > 0.0:
            return math.inf, -1, (0.0, 0.0)
        d = d / math.hypot(d[0], d[1])
        e: npt.NDArray[np.intp] | slice = slice(None)
        if self._count > self.SMALL and math.isfinite(length):
            q = p + length * d
            boxes = np.all((self._lo <= np.maximum(p, q)) & (self._hi >= np.minimum(p, q)), axis=1)
            e = np.flatnonzero(boxes[self._owner])
        ab, ap, owner, len2 = self._ab[e], self._a[e] - p, self._owner[e], self._len2[e]
        denom = d[0] * ab[:, 1] - d[1] * ab[:, 0]
        with np.errstate(divide='ignore', invalid='ignore'):
            t = (ap[:, 0] * ab[:, 1] - ap[:, 1] * ab[:, 0]) / denom
            s = (ap[:, 0] * d[1] - ap[:, 1] * d[0]) / denom
        hit = (denom != 0.0) & (s >= 0.0) & (s <= 1.0) & (t >= 0.0) & (t <= length)
        if not np.any(hit):
            return math.inf, -1, (0.0, 0.0)
        i = int(np.flatnonzero(hit)[np.argmin(t[hit])])
        normal = np.array([-ab[i, 1], ab[i, 0]]) / math.sqrt(len2[i])
        if float(normal @ d) > 0.0:
            normal = -normal
        return float(t[i]), int(owner[i]), (float(normal[0]), float(normal[1]))


class LivePolygons:
    """The :class:`PolygonSet` of a changing sequence of obstacles (items with ``.polygon``).

    The set is rebuilt only when the sequence changes (item identity), which for the
    true obstacles is once per appearance or vanishing, not once per step. Indices in
    the answers of :meth:`update`'s set are positions in the last sequence given.
    """

    def __init__(self) -> None:
        self._items: tuple[Any, ...] = ()
        self._set = PolygonSet([])

    def update(self, items: Sequence[Any]) -> PolygonSet:
        """The set of ``items``' polygons."""
        items = tuple(items)
        if len(items) != len(self._items) or any(
                a is not b for a, b in zip(items, self._items)):
            self._items = items
            self._set = PolygonSet([item.polygon for item in items])
        return self._set
