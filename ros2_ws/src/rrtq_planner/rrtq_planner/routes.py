"""The planner alone on a fixed world: RRT^X, then the shortest of its corridors.

What ``rrtq plan`` runs (:mod:`rrtq_bringup.plan_cli` reads the world and the arguments):
every obstacle grown by the robot radius R (:func:`grow_polygon`, a polygon that contains
the exact Minkowski sum with the disc); RRT^X plans on the grown polygons for 85 % of the
wall-time budget; in the rest, the tree path and graph paths through other corridors of
the RRT^X graph (:func:`candidate_routes`) are shortened by
:class:`rrtq_planner.shortcut.Shortener` and the shortest is returned.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .rrtx import RRTX, PlanStatus, RRTXConfig
from .safety import grow_polygon
from .shortcut import Shortener, path_length

# m added to R when growing: the grown polygons only touch the disc-grown set at
# tangent points, so a path brushing one would sit at R minus rounding error.
CLEARANCE_SLACK = 1e-6
# m added around an Otte environment's bounding box, beyond R.
OTTE_PADDING = 1.0
# RRT^X iterations between two looks at the clock.
_CHUNK = 25
# Steer distance delta as a share of the larger side of the bounds.  One query
# gains from long edges (20 m in [-50, 50]^2: raw paths ~1.5 % shorter at the
# same time than delta = 5 m, the node's choice, which favours quick repairs).
STEER_SHARE = 0.2
# Share of --time given to RRT^X; the rest shortens candidate paths.
RRTX_SHARE = 0.85
# Share of samples drawn about the current path's bends (RRTXConfig.path_bias): on
# rand_Static the raw path after 1 / 2 / 5 s of CPU is 1.016 / 1.008 / 1.006 x the
# optimum against 1.027 / 1.020 / 1.011 with uniform samples (5 seeds, median,
# measured side by side 2026-12-01); one query gains from it, the planner node keeps
# uniform samples.
PATH_BIAS = 0.3
# Candidate routes: graph paths via nodes whose best path through them costs at
# most this factor times the best, at least CORRIDOR_SPREAD m from the routes
# already taken, at most MAX_CANDIDATES of them.
CORRIDOR_SLACK = 1.15
CORRIDOR_SPREAD = 2.0
MAX_CANDIDATES = 20



def default_bounds(polygons: Sequence[np.ndarray], start: np.ndarray, goal: np.ndarray,
                   radius: float) -> tuple[float, float, float, float]:
    """Bounding box of obstacles, start and goal, padded by R + 1 m.

    The shortest path stays in the convex hull of the grown obstacles' vertices
    and the end points, which this box contains.
    """
    pts = np.vstack([start, goal, *polygons]) if polygons else np.vstack([start, goal])
    lo = pts.min(axis=0) - (radius + OTTE_PADDING)
    hi = pts.max(axis=0) + (radius + OTTE_PADDING)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


@dataclass(frozen=True)
class PlanResult:
    """What ``rrtq plan`` prints."""

    path: np.ndarray          # (k, 2) m, start first, goal last; (0, 2) without a path
    cost: float | None        # m, length of ``path``
    rrtx_cost: float | None   # m, the raw RRT^X tree path
    nodes: int
    iterations: int
    time_s: float

    def to_json(self) -> str:
        """One line of JSON."""
        return json.dumps({
            'path': [[float(x), float(y)] for x, y in self.path],
            'cost': self.cost, 'rrtx_cost': self.rrtx_cost, 'nodes': self.nodes,
            'iterations': self.iterations, 'time_s': round(self.time_s, 4)})


def grow(polygons: Sequence[np.ndarray], radius: float) -> list[np.ndarray]:
    """Each polygon grown by ``radius`` (+ :data:`CLEARANCE_SLACK` when radius > 0)."""
    margin = radius + CLEARANCE_SLACK if radius > 0.0 else 0.0
    return [grow_polygon(p, margin) for p in polygons]


def _chain(pred: np.ndarray, source: int, node: int) -> list[int]:
    """Nodes from ``source`` to ``node`` along Dijkstra predecessors."""
    out = [node]
    while out[-1] != source:
        out.append(int(pred[out[-1]]))
    return out[::-1]


def _distance_to_path(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Distance (m) from each point (n, 2) to the polyline (k, 2)."""
    a = path[:-1][None]
    ab = (path[1:] - path[:-1])[None]
    ap = points[:, None, :] - a
    len2 = np.maximum(np.einsum('ijk,ijk->ij', ab, ab), 1e-300)
    t = np.clip(np.einsum('ijk,ijk->ij', ap, ab) / len2, 0.0, 1.0)
    d = ap - t[..., None] * ab
    return np.asarray(np.sqrt(np.einsum('ijk,ijk->ij', d, d)).min(axis=1))


def candidate_routes(planner: RRTX, start: np.ndarray) -> list[np.ndarray]:
    """Graph paths start -> goal through distinct corridors of the RRT^X graph, best first.

    The tree path is optimal on the graph, but its corridor (homotopy class) is
    not always the one whose shortened path is shortest.  Dijkstra from v_bot
    and from the goal over the planner's current edges gives, for every node,
    the best graph path through it; among nodes within CORRIDOR_SLACK of the
    best, farthest-point selection against the routes already taken picks one
    via node per corridor.
    """
    routes = [planner.path()]
    tails, heads, costs = planner.edges()
    ok = np.isfinite(costs)
    n = planner.node_count
    if planner.vbot < 0 or not ok.any():
        return routes
    graph = csr_matrix((costs[ok], (tails[ok], heads[ok])), shape=(n, n))
    dist, pred = dijkstra(graph, indices=[planner.vbot, planner.goal], return_predecessors=True)
    total = dist[0] + dist[1]
    best = float(total.min())
    if not np.isfinite(best):
        return routes
    nodes = np.flatnonzero(total <= CORRIDOR_SLACK * best)
    pos = planner.positions
    near = np.full(nodes.shape[0], np.inf)
    for _ in range(MAX_CANDIDATES - 1):
        near = np.minimum(near, _distance_to_path(pos[nodes], routes[-1]))
        k = int(np.argmax(near))
        if near[k] < CORRIDOR_SPREAD:
            break
        v = int(nodes[k])
        chain = _chain(pred[0], planner.vbot, v) + _chain(pred[1], planner.goal, v)[::-1][1:]
        route = pos[chain]
        if not np.array_equal(route[0], start):
            route = np.vstack((start, route))
        routes.append(route)
    return routes


def make_planner(grown: Sequence[np.ndarray], start: np.ndarray, goal: np.ndarray,
                 bounds: tuple[float, float, float, float], radius: float,
                 seed: int) -> RRTX:
    """RRT^X as ``rrtq plan`` configures it, obstacles added and the robot placed."""
    x0, x1, y0, y1 = bounds
    # Samples stay R from the border unless that leaves no room (tiny bounds).
    sample_margin = radius if min(x1 - x0, y1 - y0) > 4.0 * radius else 0.0
    config = RRTXConfig(goal=(float(goal[0]), float(goal[1])), bounds=bounds,
                        steer_distance=STEER_SHARE * max(x1 - x0, y1 - y0),
                        robot_radius=sample_margin, path_bias=PATH_BIAS)
    planner = RRTX(config, np.random.default_rng(seed))
    for i, poly in enumerate(grown):
        planner.add_obstacle(f'obstacle_{i}', poly)
    planner.set_robot(start)
    return planner


def shortest_route(planner: RRTX, start: np.ndarray, shortener: Shortener,
                   deadline: float = math.inf) -> np.ndarray:
    """The shortest of the shortened candidate routes (the tree path always included).

    Routes are taken in the order of :func:`candidate_routes` until
    ``deadline`` (a ``time.perf_counter()`` value) passes.  A start outside the
    planner's region (within R of the bounds) keeps its leg to the region's
    nearest point, where the route joins the tree; the rest is shortened, and
    stays in the region, which is convex.
    """
    best: np.ndarray | None = None
    for route in candidate_routes(planner, start):
        if best is not None and time.perf_counter() >= deadline:
            break
        head = route[:0]
        if len(route) > 1 and not planner.region.contains(route[0])[0]:
            head, route = route[:1], route[1:]
        if len(route) == 1 and len(head) == 0:  # the robot sits on the goal
            route = np.vstack((route, route))
        short = np.vstack((head, shortener.simplify(route)))
        if best is None or path_length(short) < path_length(best):
            best = short
    assert best is not None
    return best


def plan(polygons: Sequence[np.ndarray], start: np.ndarray, goal: np.ndarray,
         bounds: tuple[float, float, float, float], radius: float, budget_s: float,
         seed: int) -> PlanResult:
    """Grow, plan with RRT^X, shorten the best corridors, all within ``budget_s``.

    RRT^X runs for RRTX_SHARE of the wall-time budget; then the candidate routes
    (:func:`candidate_routes`, the tree path first) are shortened one by one
    until the budget is spent, and the shortest result is returned.  The tree
    path is always shortened, even late.

    Parameters
    ----------
    polygons : sequence of numpy.ndarray
        Original obstacles (k, 2), m.
    start, goal : numpy.ndarray
        (2,), m; assumed valid (see :func:`check_point`).
    bounds : tuple of float
        Sampling region (x_min, x_max, y_min, y_max), m.
    radius : float
        Robot radius R (m).
    budget_s : float
        Wall time, s.
    seed : int
        Seed of the planner's generator.
    """
    t0 = time.perf_counter()
    grown = grow(polygons, radius)
    planner = make_planner(grown, start, goal, bounds, radius, seed)
    shortener = Shortener(grown)
    while time.perf_counter() < t0 + RRTX_SHARE * budget_s:
        planner.run(_CHUNK)
    if planner.status is not PlanStatus.FOUND:
        return PlanResult(np.zeros((0, 2)), None, None, planner.node_count,
                          planner.iterations, time.perf_counter() - t0)
    best = shortest_route(planner, start, shortener, deadline=t0 + budget_s)
    return PlanResult(best, path_length(best), planner.cost(), planner.node_count,
                      planner.iterations, time.perf_counter() - t0)
