"""Obstacle changes in RRT^X: Algorithms 7-11 of Otte & Frazzoli (IJRR 2016).

An edge's cost is inf while at least one obstacle blocks it; each obstacle
remembers the edges it blocked, and a block count per edge makes overlapping
obstacles exact: removing one obstacle restores only the edges that no other
obstacle blocks.  Edges created while an obstacle exists never cross it
(they are collision-checked in ``extend``), so that record stays complete.

The region (the bounds shrunk by the margin, :class:`rrtq_planner.bounds.Region`)
changes like one more obstacle: when the margin moves, the edges with an end
outside the new region (the goal excepted) are its blocked edges, and those no
longer outside are restored.  The region is convex and new nodes are placed in
it, so an edge created while it holds is inside it: that record stays complete too.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .bounds import Region
from .geometry import segments_hit_polygon
from .graph import INF

if TYPE_CHECKING:
    from .geometry import ObstacleMap
    from .graph import RRTXGraph
    from .heap import KeyedQueue
    from .neighbors import PointIndex
    from .rrtx_config import RRTXConfig


class ObstacleMixin:
    """Obstacle handling shared by :class:`rrtq_planner.rrtx.RRTX`."""

    config: RRTXConfig
    graph: RRTXGraph
    queue: KeyedQueue
    index: PointIndex
    obstacles: ObstacleMap
    radius: float
    vbot: int
    goal: int
    region: Region
    _eps: float
    _blocked_by: dict[str, np.ndarray]
    _region_blocked: np.ndarray
    _orphans: list[int]

    if TYPE_CHECKING:  # provided by RewireMixin / RobotMixin; declared for mypy only

        def update_lmc(self, v: int) -> None: ...

        def verify_queue(self, v: int) -> None: ...

        def reduce_inconsistency(self) -> None: ...

        def _check_robot_target(self) -> None: ...

    def add_obstacle(self, obstacle_id: str, polygon: np.ndarray) -> None:
        """Add (or move) one obstacle and repair (Algorithm 7, appeared obstacles).

        Parameters
        ----------
        obstacle_id : str
            Key used to remove it later.
        polygon : numpy.ndarray
            Vertices (k, 2) in m, already grown by the robot radius; closed set.
        """
        self.update_obstacles(added={obstacle_id: polygon})

    def remove_obstacle(self, obstacle_id: str) -> None:
        """Remove one obstacle and repair (Algorithm 7, vanished obstacles)."""
        self.update_obstacles(removed=[obstacle_id])

    def update_obstacles(
        self,
        added: dict[str, np.ndarray] | None = None,
        removed: list[str] | None = None,
        margin: float | None = None,
    ) -> None:
        """Algorithm 7: apply vanished, then appeared obstacles, then repair.

        An id in ``added`` that is already present is a move (or a regrowth,
        as when the safety margin grows): only the edges the old polygon
        blocked and the new one does not are restored (with the vanished
        obstacles), and only the edges the new one blocks and the old one did
        not are blocked (with the appeared ones).  A ``margin`` (m) other than
        the region's moves the region to the bounds shrunk by it, in the same way.

        Raises
        ------
        KeyError
            If a removed id is unknown.
        """
        added = dict(added or {})
        removed = list(removed or [])
        for oid in removed:
            if oid not in self.obstacles:
                raise KeyError(f"unknown obstacle id {oid!r}")
        self.radius = self.config.ball_radius(self.graph.n)
        restored = []
        for oid in removed:
            self.obstacles.remove(oid)
            restored.append(self._unblock(self._blocked_by.pop(oid)))
        newly: list[np.ndarray] = []
        for oid, polygon in added.items():
            old = self._blocked_by.get(oid)
            hit = self._edges_through(self.obstacles.add(oid, polygon))
            self._blocked_by[oid] = hit
            if old is None:
                newly.append(hit)
            else:
                restored.append(self._unblock(np.setdiff1d(old, hit, assume_unique=True)))
                newly.append(np.setdiff1d(hit, old, assume_unique=True))
        if margin is not None and margin != self.region.margin:
            old = self._region_blocked
            self.region = Region(self.config.bounds, margin)
            hit = self._edges_outside()
            self._region_blocked = hit
            restored.append(self._unblock(np.setdiff1d(old, hit, assume_unique=True)))
            newly.append(np.setdiff1d(hit, old, assume_unique=True))
        if restored:
            self._remove_obstacle(np.concatenate(restored))
            self.reduce_inconsistency()
        if newly:
            for e in newly:
                self._add_obstacle(e)
            self.propagate_descendants()
            if self.vbot >= 0:
                self.verify_queue(self.vbot)
            self.reduce_inconsistency()
        self._check_robot_target()

    def _edges_through(self, poly: np.ndarray) -> np.ndarray:
        """Ids of the edges whose segment meets the closed polygon."""
        gr = self.graph
        lo = poly.min(axis=0)
        hi = poly.max(axis=0)
        # Edges are at most delta long, so an edge meeting the polygon has its
        # creating endpoint (the one whose N0+ holds it) within delta of it.
        reach = 0.5 * float(np.hypot(*(hi - lo))) + self.config.steer_distance + 1e-6
        rows = self.index.within(0.5 * (lo + hi), reach)
        owner, e, _ = gr.out_lists.gather(rows)
        e = e[gr.ea[e] == owner]
        elo = gr.elo[e]
        ehi = gr.ehi[e]
        cand = e[
            (elo[:, 0] <= hi[0])
            & (ehi[:, 0] >= lo[0])
            & (elo[:, 1] <= hi[1])
            & (ehi[:, 1] >= lo[1])
        ]
        hit = segments_hit_polygon(gr.pos[gr.ea[cand]], gr.pos[gr.eb[cand]], poly)
        return np.sort(cand[hit])

    def _edges_outside(self) -> np.ndarray:
        """Ids (ascending) of the edges with an end outside the region (the goal is inside)."""
        gr = self.graph
        inside = self.region.contains(gr.pos[: gr.n])
        inside[self.goal] = True
        ne = gr.ne
        return np.flatnonzero(~(inside[gr.ea[:ne]] & inside[gr.eb[:ne]]))

    def _add_obstacle(self, e: np.ndarray) -> None:
        """Algorithm 11: block edges ``e`` (those through a new obstacle), orphan tails."""
        gr = self.graph
        gr.eblock[e] += 1
        gr.ecost[e] = INF
        a = gr.ea[e]
        b = gr.eb[e]
        for v in np.concatenate((a[gr.parent[a] == b], b[gr.parent[b] == a])).tolist():
            self.verify_orphan(v)

    def _unblock(self, e: np.ndarray) -> np.ndarray:
        """Lift one obstacle's block from edges ``e``; return those now free."""
        gr = self.graph
        gr.eblock[e] -= 1
        e = e[gr.eblock[e] == 0]
        gr.ecost[e] = gr.elen[e]
        return e

    def _remove_obstacle(self, e: np.ndarray) -> None:
        """Algorithm 10: update the tails of the restored edges ``e``.

        A tail is queued when g - lmc > epsilon (the paper: g != lmc), so that
        decreases within epsilon are not propagated, as everywhere else.
        """
        gr = self.graph
        tails = np.unique(np.concatenate((gr.ea[e], gr.eb[e][gr.eback[e]])))
        g = gr.g
        lmc = gr.lmc
        for v in tails.tolist():
            self.update_lmc(v)
            if g[v] > lmc[v] + self._eps:
                self.verify_queue(v)

    def verify_orphan(self, v: int) -> None:
        """Algorithm 9: take v out of Q and into the orphan set V_c^T."""
        if not self.graph.orphan[v]:
            self.queue.remove(v)
            self.graph.orphan[v] = True
            self._orphans.append(v)

    def propagate_descendants(self) -> None:
        """Algorithm 8: orphan all descendants, then re-root them in one batch.

        Collecting the descendants and resetting them (g = lmc = inf, no
        parent) are the paper's steps.  In between, the paper sets g(u) = inf
        for the non-orphan out-neighbours u of every orphan (and its parent)
        and queues them; popping them offers them as parents to the orphans,
        which are then popped one by one: a Dijkstra search over the orphan
        subgraph, seeded with the best offers.  Here that search runs as one
        ``scipy`` Dijkstra from a virtual source whose edges carry each
        orphan's best offer d(v, u) + lmc(u), so each orphan gets its exact
        lmc = g and parent at once.  Afterwards every non-orphan
        in-neighbour w of an orphan is rewired if lmc(w) > d(w, v) + g(v) and
        queued if that leaves it inconsistent, which restores the invariants of
        ``reduce_inconsistency`` (so its bound, and exactness at epsilon = 0,
        still hold).  Per orphan this costs microseconds instead of a pop.
        """
        orph = self._orphans
        if not orph:
            return
        gr = self.graph
        flag = gr.orphan
        children = gr.children
        q = self.queue
        i = 0
        while i < len(orph):
            for c in children[orph[i]]:
                if not flag[c]:
                    flag[c] = True
                    q.remove(c)
                    orph.append(c)
            i += 1
        rows = np.array(orph, dtype=np.intp)
        for v in orph:
            gr.detach(v)
        gr.g[rows] = INF
        gr.lmc[rows] = INF
        self._orphans = []
        lmc_new, parent_new = self._reroot(rows)
        for v, p, c in zip(rows.tolist(), parent_new.tolist(), lmc_new.tolist()):
            flag[v] = False
            if p >= 0:
                gr.make_parent_of(p, v)
                gr.lmc[v] = c
                gr.g[v] = c
        # Offer the re-rooted orphans to their non-orphan in-neighbours.
        heads, e, tails = gr.in_lists.gather(rows[parent_new >= 0])
        live = (gr.eb[e] == heads) | gr.eback[e]  # skip lazily culled entries
        heads, e, tails = heads[live], e[live], tails[live]
        if tails.shape[0] == 0:
            return
        lmc = gr.lmc
        via = gr.ecost[e] + lmc[heads]
        better = (lmc[tails] > via).nonzero()[0]
        if better.shape[0] == 0:
            return
        order = better[np.lexsort((via[better], tails[better]))]
        first = np.ones(order.shape[0], dtype=bool)
        first[1:] = tails[order[1:]] != tails[order[:-1]]
        g = gr.g
        for w, v, c in zip(tails[order[first]].tolist(), heads[order[first]].tolist(),
                           via[order[first]].tolist()):
            lmc[w] = c
            gr.make_parent_of(v, w)
            if g[w] > c + self._eps:
                self.verify_queue(w)

    def _reroot(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shortest cost-to-goal and parent of each orphan in ``rows``.

        Paths may run through other orphans and must leave the orphan set
        through a non-orphan u, which contributes lmc(u).  Returns lmc (inf if
        cut off) and parent (-1 if cut off), aligned with ``rows``.
        """
        gr = self.graph
        m = rows.shape[0]
        local = np.full(gr.n, -1, dtype=np.intp)
        local[rows] = np.arange(m)
        tails, e, heads = gr.out_lists.gather(rows)
        cost = gr.ecost[e]
        ok = cost < INF
        tails = tails[ok]
        heads = heads[ok]
        cost = cost[ok]
        inner = gr.orphan[heads]
        # Best exit of each orphan: min over non-orphan heads of d + lmc(head).
        bt = tails[~inner]
        bh = heads[~inner]
        via = cost[~inner] + gr.lmc[bh]
        fin = via < INF
        bt, bh, via = bt[fin], bh[fin], via[fin]
        order = np.lexsort((via, bt))
        first = np.ones(order.shape[0], dtype=bool)
        first[1:] = bt[order[1:]] != bt[order[:-1]]
        best = order[first]
        exit_node = np.full(m, -1, dtype=np.intp)
        exit_node[local[bt[best]]] = bh[best]
        # Reverse the orphan-orphan edges; node m is the virtual source.
        src = np.concatenate((local[heads[inner]], np.full(best.shape[0], m)))
        dst = np.concatenate((local[tails[inner]], local[bt[best]]))
        w = np.concatenate((cost[inner], via[best]))
        graph = csr_matrix((w, (src, dst)), shape=(m + 1, m + 1))
        dist, pred = dijkstra(graph, directed=True, indices=m, return_predecessors=True)
        dist = dist[:m]
        pred = pred[:m]
        parent = np.full(m, -1, dtype=np.intp)
        reached = dist < INF
        via_src = reached & (pred == m)
        parent[via_src] = exit_node[via_src]
        inner_p = reached & ~via_src
        parent[inner_p] = rows[pred[inner_p]]
        return dist, parent
