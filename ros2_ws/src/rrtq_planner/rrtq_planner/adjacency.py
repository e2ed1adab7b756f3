"""Per-node lists of (edge id, neighbour) stored in blocks of two flat arrays.

Node v owns the slots ``start[v] .. start[v] + cap[v]`` of the arrays
``edge`` and ``node``; its list is the first ``count[v]`` of them.  Reading a
list is a slice (a view, no allocation); appending one entry to each of many
nodes is a few vectorised assignments; a full block is moved to the end of
the arrays with twice the room (amortised O(1)).  Entries are removed by
compacting a list in place with a boolean mask.
"""

from __future__ import annotations

import numpy as np


def _grow(arr: np.ndarray, size: int) -> np.ndarray:
    new = np.zeros(size, dtype=arr.dtype)
    new[: arr.shape[0]] = arr
    return new


class BlockLists:
    """A growable family of integer-pair lists, one per node.

    Parameters
    ----------
    nodes : int
        Initial node capacity.
    slots : int
        Initial slot capacity.
    """

    def __init__(self, nodes: int = 1024, slots: int = 1 << 16) -> None:
        self.edge = np.zeros(slots, dtype=np.intp)
        self.node = np.zeros(slots, dtype=np.intp)
        self.start = np.zeros(nodes, dtype=np.intp)
        self.count = np.zeros(nodes, dtype=np.intp)
        self.cap = np.zeros(nodes, dtype=np.intp)
        self.n = 0
        self._end = 0

    def _reserve(self, slots: int) -> int:
        """Return the first of ``slots`` fresh slots at the end."""
        s = self._end
        if s + slots > self.edge.shape[0]:
            size = max(2 * self.edge.shape[0], s + slots)
            self.edge = _grow(self.edge, size)
            self.node = _grow(self.node, size)
        self._end = s + slots
        return s

    def add_row(self, edges: np.ndarray, nodes: np.ndarray, room: int) -> int:
        """Append a new list holding ``edges``/``nodes`` with ``room`` spare slots."""
        v = self.n
        if v == self.start.shape[0]:
            size = 2 * v
            self.start = _grow(self.start, size)
            self.count = _grow(self.count, size)
            self.cap = _grow(self.cap, size)
        k = edges.shape[0]
        cap = k + room
        s = self._reserve(cap)
        self.edge[s : s + k] = edges
        self.node[s : s + k] = nodes
        self.start[v] = s
        self.count[v] = k
        self.cap[v] = cap
        self.n = v + 1
        return v

    def append(self, rows: np.ndarray, edges: np.ndarray, nodes: np.ndarray) -> None:
        """Append ``(edges[i], nodes[i])`` to list ``rows[i]`` (rows distinct)."""
        cnt = self.count[rows]
        full = cnt == self.cap[rows]
        if full.any():
            for v in rows[full].tolist():
                self._relocate(v, 2 * int(self.cap[v]) + 4)
        at = self.start[rows] + cnt
        self.edge[at] = edges
        self.node[at] = nodes
        self.count[rows] = cnt + 1

    def extend_row(self, v: int, edges: np.ndarray, nodes: np.ndarray) -> None:
        """Append several entries to list v."""
        k = int(self.count[v])
        m = edges.shape[0]
        if k + m > self.cap[v]:
            self._relocate(v, 2 * (k + m) + 4)
        s = int(self.start[v]) + k
        self.edge[s : s + m] = edges
        self.node[s : s + m] = nodes
        self.count[v] = k + m

    def _relocate(self, v: int, cap: int) -> None:
        s_old = int(self.start[v])
        k = int(self.count[v])
        s = self._reserve(cap)
        self.edge[s : s + k] = self.edge[s_old : s_old + k]
        self.node[s : s + k] = self.node[s_old : s_old + k]
        self.start[v] = s
        self.cap[v] = cap

    def get(self, v: int) -> tuple[np.ndarray, np.ndarray]:
        """Return views of list v: (edge ids, neighbours), invalid after any change."""
        s = self.start[v]
        t = s + self.count[v]
        return self.edge[s:t], self.node[s:t]

    def gather(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Concatenate the lists of ``rows``: (owning row, edge id, neighbour) arrays."""
        counts = self.count[rows]
        total = int(counts.sum())
        ends = np.cumsum(counts)
        at = np.repeat(self.start[rows] - (ends - counts), counts) + np.arange(total)
        return np.repeat(rows, counts), self.edge[at], self.node[at]

    def keep(self, v: int, mask: np.ndarray) -> None:
        """Keep only the entries of list v where ``mask`` (aligned with ``get(v)``) holds."""
        s = int(self.start[v])
        k = int(self.count[v])
        sel = mask.nonzero()[0]
        m = sel.shape[0]
        self.edge[s : s + m] = self.edge[s : s + k][sel]
        self.node[s : s + m] = self.node[s : s + k][sel]
        self.count[v] = m
