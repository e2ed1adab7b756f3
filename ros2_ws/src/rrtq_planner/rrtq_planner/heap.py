"""Keyed priority queue of node indices for RRT^X (the paper's Q).

Otte & Frazzoli (IJRR 2016) order Q by the key (min(g, lmc), g) and need
``verrifyQueue`` (insert or change the key, Algorithm 12) and removal of an
orphan (``verrifyOrphan``, Algorithm 9).  A binary heap with lazy deletion is
used: every insertion or key change pushes a fresh entry stamped with a
version number, and stale entries are skipped when they reach the top.  This
keeps all heap work inside CPython's C ``heapq`` and costs O(log n) per
decrease-key, increase-key or removal.  Ties on the key are broken by the
order of the last key change, so the order is deterministic.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator

import numpy as np

_Entry = tuple[float, float, int, int]


class KeyedQueue:
    """Min-priority queue of integer ids keyed by ``(k1, k2)``.

    Parameters
    ----------
    capacity : int
        Initial number of ids the membership arrays hold; grows on demand.
    """

    def __init__(self, capacity: int = 1024) -> None:
        self._heap: list[_Entry] = []
        # Python lists: scalar access from Python is faster than on arrays.
        self._stamp = [0] * capacity
        self._member = [False] * capacity
        self._key1 = [0.0] * capacity
        self._key2 = [0.0] * capacity
        self._counter = 0
        self._size = 0

    def _grow(self, node: int) -> None:
        extra = max(len(self._member), node + 1 - len(self._member))
        self._stamp.extend([0] * extra)
        self._member.extend([False] * extra)
        self._key1.extend([0.0] * extra)
        self._key2.extend([0.0] * extra)

    def __len__(self) -> int:
        return self._size

    def __contains__(self, node: int) -> bool:
        return node < len(self._member) and self._member[node]

    def push(self, node: int, k1: float, k2: float) -> None:
        """Insert ``node`` or change its key (decrease or increase).

        Parameters
        ----------
        node : int
            Node index.
        k1, k2 : float
            The key (min(g, lmc), g) in metres.
        """
        if node >= len(self._member):
            self._grow(node)
        if self._member[node] and self._key1[node] == k1 and self._key2[node] == k2:
            return
        self._counter += 1
        if not self._member[node]:
            self._member[node] = True
            self._size += 1
        self._stamp[node] = self._counter
        self._key1[node] = k1
        self._key2[node] = k2
        heapq.heappush(self._heap, (k1, k2, self._counter, node))
        if len(self._heap) > 4 * self._size + 1024:
            self._compact()

    def remove(self, node: int) -> None:
        """Remove ``node`` if it is queued (no-op otherwise)."""
        if node < len(self._member) and self._member[node]:
            self._member[node] = False
            self._size -= 1

    def _discard_stale(self) -> None:
        heap = self._heap
        member = self._member
        stamp = self._stamp
        while heap:
            _, _, st, node = heap[0]
            if member[node] and stamp[node] == st:
                return
            heapq.heappop(heap)

    def top_key(self) -> tuple[float, float] | None:
        """Key of the minimum entry, or ``None`` when empty."""
        if self._size == 0:
            return None
        self._discard_stale()
        k1, k2, _, _ = self._heap[0]
        return k1, k2

    def pop(self) -> int:
        """Remove and return the node with the smallest key.

        Raises
        ------
        IndexError
            If the queue is empty.
        """
        if self._size == 0:
            raise IndexError("pop from an empty KeyedQueue")
        self._discard_stale()
        _, _, _, node = heapq.heappop(self._heap)
        self._member[node] = False
        self._size -= 1
        return node

    def key(self, node: int) -> tuple[float, float]:
        """Return the stored key of a queued node."""
        return self._key1[node], self._key2[node]

    def nodes(self) -> Iterator[int]:
        """Queued node ids, in no particular order."""
        return (i for i, m in enumerate(self._member) if m)

    def membership(self, n: int) -> np.ndarray:
        """Boolean membership flags of ids ``0 .. n-1`` (a copy)."""
        out = np.zeros(n, dtype=bool)
        m = min(n, len(self._member))
        out[:m] = self._member[:m]
        return out

    def _compact(self) -> None:
        member = self._member
        stamp = self._stamp
        self._heap = [e for e in self._heap if member[e[3]] and stamp[e[3]] == e[2]]
        heapq.heapify(self._heap)
