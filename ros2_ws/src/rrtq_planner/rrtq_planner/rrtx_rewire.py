"""Rewiring in RRT^X: Algorithms 3-5, 12 and 13 of Otte & Frazzoli (IJRR 2016).

Culling a node's neighbour lists to r(n), offering a node as parent to its
in-neighbours, its best parent among its out-neighbours, and the queue Q that
reduce_inconsistency works off until v_bot is consistent (its docstring proves
the bound on g(v_bot)); :mod:`rrtq_planner.rrtx` explains the deviations from
the paper.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .graph import INF

if TYPE_CHECKING:
    from .graph import RRTXGraph
    from .heap import KeyedQueue

# r(n) shrinks at every insertion; culling a node's list for each slight
# shrink would cost more per pop than the few extra neighbours it removes.
_CULL_SLACK = 1.05


class RewireMixin:
    """Rewiring and the queue of :class:`rrtq_planner.rrtx.RRTX`."""

    graph: RRTXGraph
    queue: KeyedQueue
    radius: float
    vbot: int
    goal: int
    _eps: float
    _orphans: list[int]

    def cull_neighbors(self, v: int) -> None:
        """Algorithm 3 with r = r(n) (geometric length, see the module notes).

        Inside update_lmc / rewire a list is culled only once its longest
        running edge exceeds 1.05 r(n) (then down to r(n)); this call is exact.
        """
        self.graph.cull(v, self.radius)

    def rewire_neighbors(self, v: int) -> None:
        """Algorithm 4: offer v as parent to its in-neighbours if g(v) - lmc(v) > eps."""
        if self.graph.g[v] > self.graph.lmc[v] + self._eps:
            self._rewire(v)

    def _rewire(self, v: int) -> None:
        """Algorithm 4 without its entry test (callers decide)."""
        self._update_and_rewire(v, update=False, rewire=True)

    def update_lmc(self, v: int) -> None:
        """Algorithm 13: best parent among non-orphan out-neighbours not below v.

        Culls v's running out-list first; lmc(v) only ever decreases here.
        """
        self._update_and_rewire(v, update=True, rewire=False)

    def verify_queue(self, v: int) -> None:
        """Algorithm 12: insert v into Q or update its key (min(g, lmc), g)."""
        g = self.graph.g.item(v)
        lmc = self.graph.lmc.item(v)
        self.queue.push(v, lmc if lmc < g else g, g)

    def reduce_inconsistency(self) -> None:
        """Algorithm 5: process Q until v_bot is consistent and settled.

        Loops while Q is non-empty and (top key < key(v_bot), or g(v_bot) !=
        lmc(v_bot), or g(v_bot) = inf, or v_bot in Q); with no v_bot it drains Q.
        Bound.  Two invariants hold between calls: (I1) every node w outside Q
        has g(w) >= lmc(w) and g(w) - lmc(w) <= eps; (I2) for every edge
        u -> w with w outside Q, lmc(u) <= d(u, w) + g(w).  Take any path
        x_0 = v_bot, ..., x_k = goal and let x_j be its queued node nearest
        the goal (j = 0 if none is queued).  Chaining I2 and I1 along
        x_j .. x_k gives lmc(x_j) <= cost(x_j .. x_k) + (k - j - 1) eps, and
        on exit key(v_bot) <= key(x_j) <= lmc(x_j), so g(v_bot) <=
        cost(path) + (k - 1) eps.  Since every lmc is the cost of a real
        parent chain, D <= g(v_bot) <= D + (k - 1) eps, with D the
        shortest-path cost over the planner's current edges and k the number
        of edges of a shortest path; eps = 0 gives g(v_bot) = D exactly.
        """
        q = self.queue
        gr = self.graph
        g = gr.g
        lmc = gr.lmc
        eps = self._eps
        vb = self.vbot
        if vb >= 0 and g[vb] != lmc[vb] and vb not in q:
            self.verify_queue(vb)
        while len(q):
            if vb >= 0:
                gb = g.item(vb)
                lb = lmc.item(vb)
                if gb == lb and gb < INF and vb not in q:
                    top = q.top_key()
                    if top is None or not top < (lb, gb):
                        break
            v = q.pop()
            gv = g.item(v)
            lv = lmc.item(v)
            if gv > lv + eps or (v == vb and gv != lv):
                self._update_and_rewire(v, update=True, rewire=True)
                lv = lmc.item(v)
            g[v] = lv

    def _update_and_rewire(self, v: int, update: bool, rewire: bool) -> None:
        """Cull, then ``update_lmc`` (Alg. 13) and/or ``rewire`` (Alg. 4) of v.

        One body for both steps: reduce_inconsistency runs them back to back
        once per queue pop, the planner's innermost loop, so lookups are
        shared and makeParentOf / verrifyQueue are inlined in the rewiring.
        """
        gr = self.graph
        r = self.radius
        if gr.max_running.item(v) > r * _CULL_SLACK:
            gr.cull(v, r)
        lmc = gr.lmc
        ecost = gr.ecost
        parent = gr.parent
        lv = lmc.item(v)
        if update and v != self.goal:
            ol = gr.out_lists
            s = ol.start.item(v)
            t = s + ol.count.item(v)
            if t > s:
                heads = ol.node[s:t]
                costs = ecost[ol.edge[s:t]]
                costs += lmc[heads]
                # The paper also skips children u of v; no mask is needed:
                # lmc(u) was set to d(u, v) + lmc(v) and lmc(v) has only
                # decreased since, so d(v, u) + lmc(u) > lmc(v) never wins.
                if self._orphans:
                    costs[gr.orphan[heads]] = INF
                j = costs.argmin()
                c = costs.item(j)
                if c < lv:
                    lmc[v] = c
                    lv = c
                    gr.make_parent_of(heads.item(j), v)
        if not rewire:
            return
        if gr.in_dead.item(v):
            gr.compact_in(v)
        il = gr.in_lists
        s = il.start.item(v)
        t = s + il.count.item(v)
        tails = il.node[s:t]
        cand = ecost[il.edge[s:t]]
        cand += lv
        idx = (lmc[tails] > cand).nonzero()[0]
        if idx.shape[0] == 0:
            return
        g = gr.g
        children = gr.children
        mine = children[v]
        push = self.queue.push
        eps = self._eps
        par = parent.item(v)
        for u, c in zip(tails[idx].tolist(), cand[idx].tolist()):
            if u == par:
                continue
            lmc[u] = c
            old = parent.item(u)
            if old >= 0:
                children[old].discard(u)
            parent[u] = v
            mine.add(u)
            gu = g.item(u)
            if gu > c + eps:
                push(u, c, gu)
