"""Checks of an RRT^X planner computed independently of it (for rrtq_planner's tests).

Dijkstra (scipy) over the planner's own current edges (the cost-to-goal it must match,
within the bound of ``RRTX.reduce_inconsistency`` for eps > 0), a brute-force collision
check of a path against convex polygons, the invariants of its tree, neighbour lists and
queue, and a snapshot of its state to compare before and after an obstacle change. The
planner is read through its public accessors (``edges``, ``g``, ``lmc``, ``parents``,
``neighbors``, ``queue_contents``) and its graph and queue; nothing of it is imported.
"""

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

__all__ = ['assert_invariants', 'assert_matches_dijkstra', 'assert_path_clear',
           'dijkstra_to_goal', 'hops', 'inside_convex', 'snapshot']


def dijkstra_to_goal(planner):
    """Cost-to-goal of every node over the planner's current directed edges."""
    tail, head, cost = planner.edges()
    ok = np.isfinite(cost)
    n = planner.node_count
    # Reverse the edges so one search from the goal gives cost-to-goal.
    graph = csr_matrix((cost[ok], (head[ok], tail[ok])), shape=(n, n))
    dist, pred = dijkstra(graph, indices=planner.goal, return_predecessors=True)
    return dist, pred


def hops(pred, v, goal):
    k = 0
    while v != goal:
        v = pred[v]
        k += 1
    return k


def assert_matches_dijkstra(planner, tol=1e-9):
    dist, pred = dijkstra_to_goal(planner)
    g = planner.g[planner.vbot]
    if not np.isfinite(dist[planner.vbot]):
        assert g == np.inf
        return dist
    # With eps = 0 exact; else D <= g <= D + (k - 1) eps, k = edges of the
    # shortest path (the bound derived in RRTX.reduce_inconsistency).
    k = hops(pred, planner.vbot, planner.goal)
    slack = max(k - 1, 0) * planner.config.epsilon
    assert dist[planner.vbot] - tol <= g <= dist[planner.vbot] + slack + tol
    return dist


def inside_convex(points, poly):
    """Test points against a closed convex polygon, independently of the planner."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    cross = (b[:, 0] - a[:, 0]) * (points[:, None, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (
        points[:, None, 0] - a[:, 0]
    )
    return np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)


def assert_path_clear(path, polygons, spacing=0.005):
    assert path.shape[0] >= 2
    for p, q in zip(path[:-1], path[1:]):
        m = max(2, int(np.ceil(np.linalg.norm(q - p) / spacing)) + 1)
        pts = p + np.linspace(0.0, 1.0, m)[:, None] * (q - p)
        for poly in polygons:
            assert not inside_convex(pts, poly).any()


def assert_invariants(planner):
    gr = planner.graph
    n = planner.node_count
    parent = planner.parents
    lmc = planner.lmc
    g = planner.g
    eps = planner.config.epsilon
    tail, head, cost = planner.edges()
    out = {v: set() for v in range(n)}
    ecost = {}
    for t, h, c in zip(tail.tolist(), head.tolist(), cost.tolist()):
        assert h not in out[t]
        out[t].add(h)
        ecost[(t, h)] = c
    # Parents form a tree rooted at the goal; children mirror parents.
    assert parent[planner.goal] == -1 and lmc[planner.goal] == 0.0
    for v in range(n):
        p = parent[v]
        assert gr.children[v] == set(np.flatnonzero(parent == v).tolist())
        if v == planner.goal:
            continue
        if p < 0:
            assert lmc[v] == np.inf
            continue
        assert p in out[v] and np.isfinite(ecost[(v, p)])
        assert lmc[v] >= ecost[(v, p)] + lmc[p] - 1e-9
        seen, u = 0, v
        while u != planner.goal:
            u = parent[u]
            seen += 1
            assert u >= 0 and seen <= n
    # Neighbour lists are mirror images: u in N+(v) <=> v in N-(u).
    for v in range(n):
        lists = planner.neighbors(v)
        assert set(lists["out_original"]) | set(lists["out_running"]) == out[v]
        for u in lists["in_original"] + lists["in_running"]:
            assert v in out[u]
        assert not set(lists["out_original"]) & set(lists["out_running"])
    # Heap flags match membership; nodes outside Q are eps-consistent and
    # satisfy lmc(u) <= d(u, w) + g(w) on every edge u -> w.
    queued = set(planner.queue_contents())
    live = {e[3] for e in planner.queue._heap if planner.queue._stamp[e[3]] == e[2]}
    assert queued == live & queued and len(planner.queue) == len(queued)
    for w in range(n):
        if w in queued:
            continue
        assert g[w] >= lmc[w] and (g[w] == lmc[w] or g[w] - lmc[w] <= eps)
    for (u, w), c in ecost.items():
        if w not in queued and np.isfinite(g[w]) and u != planner.goal:
            assert lmc[u] <= c + g[w] + 1e-9


def snapshot(planner):
    gr = planner.graph
    return {
        "g": planner.g,
        "lmc": planner.lmc,
        "parent": planner.parents,
        "ecost": gr.ecost[: gr.ne].copy(),
        "eback": gr.eback[: gr.ne].copy(),
        "queue": planner.queue_contents(),
        "cost": planner.cost(),
    }
