"""Node and edge storage of the RRT^X graph (Otte & Frazzoli, IJRR 2016).

Every edge of RRT^X is created in ``extend`` (Algorithm 2) between the new
node ``a`` and an older node ``b`` within the ball; in position space both
directions are the same straight segment, so one undirected record holds
both.  With the paper's lists:

* ``a -> b`` lives in N0+(a) and Nr-(b).  N0+ is never culled, so this
  direction is permanent.
* ``b -> a`` lives in Nr+(b) and N0-(a).  ``cull_neighbors(b)`` (Algorithm 3)
  may drop it; the flag ``eback`` records whether it still exists.  Culling
  removes both halves, so out-lists and in-lists stay mirror images (the
  paper's cull removes b from Nr-(a), but ``b`` sits in N0-(a); removing the
  mirror entry keeps rewiring and parent search on the same graph).

Per edge the table keeps its geometric length, its current cost (the length,
or inf while at least one obstacle blocks it) and how many obstacles block it.
Arrays grow by doubling; per-node out- and in-lists are ``BlockLists``.
"""

from __future__ import annotations

import numpy as np

from .adjacency import BlockLists

INF = float("inf")


def _grown(arr: np.ndarray, size: int, fill: float | int | bool) -> np.ndarray:
    new = np.full((size,) + arr.shape[1:], fill, dtype=arr.dtype)
    new[: arr.shape[0]] = arr
    return new


class RRTXGraph:
    """Nodes (position, g, lmc, parent, children) and edges of RRT^X.

    Each node keeps its out- and in-lists (N0+ u Nr+ and N0- u Nr-) as
    (edge id, neighbour) pairs, read as array views without filtering.

    Parameters
    ----------
    capacity : int
        Initial node capacity.
    edge_capacity : int
        Initial edge capacity.
    """

    def __init__(self, capacity: int = 1024, edge_capacity: int = 16384) -> None:
        self.n = 0
        self.ne = 0
        self.pos = np.zeros((capacity, 2))
        self.g = np.full(capacity, INF)
        self.lmc = np.full(capacity, INF)
        self.parent = np.full(capacity, -1, dtype=np.intp)
        self.orphan = np.zeros(capacity, dtype=bool)
        self.max_running = np.zeros(capacity)
        self.in_dead = np.zeros(capacity, dtype=np.intp)
        self.children: list[set[int]] = []
        self.out_lists = BlockLists(capacity)
        self.in_lists = BlockLists(capacity)
        self.ea = np.zeros(edge_capacity, dtype=np.intp)
        self.eb = np.zeros(edge_capacity, dtype=np.intp)
        self.elen = np.zeros(edge_capacity)
        self.ecost = np.zeros(edge_capacity)
        self.eblock = np.zeros(edge_capacity, dtype=np.int32)
        self.eback = np.zeros(edge_capacity, dtype=bool)
        self.elo = np.zeros((edge_capacity, 2))
        self.ehi = np.zeros((edge_capacity, 2))

    # ------------------------------------------------------------------ nodes
    def add_node(self, point: np.ndarray) -> int:
        """Append a node at ``point`` with g = lmc = inf and no parent."""
        v = self.n
        if v == self.pos.shape[0]:
            cap = 2 * v
            self.pos = _grown(self.pos, cap, 0.0)
            self.g = _grown(self.g, cap, INF)
            self.lmc = _grown(self.lmc, cap, INF)
            self.parent = _grown(self.parent, cap, -1)
            self.orphan = _grown(self.orphan, cap, False)
            self.max_running = _grown(self.max_running, cap, 0.0)
            self.in_dead = _grown(self.in_dead, cap, 0)
        self.pos[v] = point
        self.children.append(set())
        empty = np.zeros(0, dtype=np.intp)
        self.out_lists.add_row(empty, empty, 0)
        self.in_lists.add_row(empty, empty, 0)
        self.n = v + 1
        return v

    def make_parent_of(self, p: int, v: int) -> None:
        """Set p+_v = p and keep the child sets C- in step (paper's makeParentOf)."""
        old = self.parent[v]
        if old >= 0:
            self.children[old].discard(v)
        self.parent[v] = p
        self.children[p].add(v)

    def detach(self, v: int) -> None:
        """Drop v's parent pointer (p+_v = None)."""
        old = self.parent[v]
        if old >= 0:
            self.children[old].discard(v)
            self.parent[v] = -1

    # ------------------------------------------------------------------ edges
    def add_edges(self, a: int, others: np.ndarray, lengths: np.ndarray) -> None:
        """Create the edges of new node ``a`` to older ``others`` (Alg. 2, 6-12)."""
        k = others.shape[0]
        e0 = self.ne
        e1 = e0 + k
        if e1 > self.ea.shape[0]:
            cap = max(2 * self.ea.shape[0], e1)
            for name, fill in (
                ("ea", 0), ("eb", 0), ("elen", 0.0), ("ecost", 0.0),
                ("eblock", 0), ("eback", False), ("elo", 0.0), ("ehi", 0.0),
            ):
                setattr(self, name, _grown(getattr(self, name), cap, fill))
        self.ea[e0:e1] = a
        self.eb[e0:e1] = others
        self.elen[e0:e1] = lengths
        self.ecost[e0:e1] = lengths
        self.eblock[e0:e1] = 0
        self.eback[e0:e1] = True
        pa = self.pos[a]
        pb = self.pos[others]
        np.minimum(pb, pa, out=self.elo[e0:e1])
        np.maximum(pb, pa, out=self.ehi[e0:e1])
        # ``others`` holds distinct nodes, so a plain gather/scatter is exact.
        self.max_running[others] = np.maximum(self.max_running[others], lengths)
        ids = np.arange(e0, e1, dtype=np.intp)
        self.out_lists.extend_row(a, ids, others)
        self.in_lists.extend_row(a, ids, others)
        mine = np.full(k, a, dtype=np.intp)
        self.out_lists.append(others, ids, mine)
        self.in_lists.append(others, ids, mine)
        self.ne = e1

    def out_edges(self, x: int) -> tuple[np.ndarray, np.ndarray]:
        """Edge ids and heads of N0+(x) u Nr+(x) (views: copy before changes)."""
        return self.out_lists.get(x)

    def in_edges(self, x: int) -> tuple[np.ndarray, np.ndarray]:
        """Edge ids and tails of N0-(x) u Nr-(x) (views: copy before changes)."""
        if self.in_dead[x]:
            self.compact_in(x)
        return self.in_lists.get(x)

    def compact_in(self, x: int) -> None:
        """Drop the in-list entries of x whose edge was culled at the other end."""
        e, _ = self.in_lists.get(x)
        self.in_lists.keep(x, (self.eb[e] == x) | self.eback[e])
        self.in_dead[x] = 0

    def cull(self, x: int, radius: float, slack: float = 1.0) -> None:
        """Drop running out-neighbours of x farther than ``radius`` (Alg. 3).

        The paper compares the trajectory cost d_pi(x, u), which is inf while an
        obstacle blocks the edge, so the reference code culls every blocked
        running edge and cannot restore it when the obstacle vanishes.  The
        geometric length is used instead: an edge is culled exactly when it is
        longer than the ball, blocked or not.  ``max_running`` (the longest
        running out-edge) makes the common case, nothing to cull, O(1); with
        ``slack`` > 1 the list is left alone until that edge exceeds
        ``slack * radius`` (then every edge longer than ``radius`` goes).  The
        mirror entries in the heads' in-lists are dropped lazily: ``in_dead``
        counts them and the in-list is compacted before it is next read.
        """
        if self.max_running[x] <= radius * slack:
            return
        e, heads = self.out_edges(x)
        running = self.ea[e] != x
        lengths = self.elen[e]
        drop = running & (lengths > radius) & (heads != self.parent[x])
        keep = running & ~drop
        self.max_running[x] = lengths[keep].max() if keep.any() else 0.0
        if drop.any():
            self.eback[e[drop]] = False
            self.in_dead[heads[drop]] += 1
            self.out_lists.keep(x, ~drop)

    def neighbor_lists(self, x: int) -> dict[str, list[int]]:
        """Return the four neighbour sets of x as sorted node lists (for inspection)."""
        e_out, n_out = self.out_edges(x)
        e_in, n_in = self.in_edges(x)
        own_out = self.ea[e_out] == x
        own_in = self.ea[e_in] == x
        return {
            "out_original": sorted(n_out[own_out].tolist()),
            "out_running": sorted(n_out[~own_out].tolist()),
            "in_original": sorted(n_in[own_in].tolist()),
            "in_running": sorted(n_in[~own_in].tolist()),
        }

    def directed_edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All current directed edges as (tail, head, cost) arrays."""
        ne = self.ne
        back = np.flatnonzero(self.eback[:ne])
        tail = np.concatenate((self.ea[:ne], self.eb[back]))
        head = np.concatenate((self.eb[:ne], self.ea[back]))
        cost = np.concatenate((self.ecost[:ne], self.ecost[back]))
        return tail, head, cost
