"""``rrtq plan ENV --start X Y --goal X Y``: the planner alone, as a command.

ENV is a scenario YAML (its obstacles that exist at t = 0, its bounds, its robot
radius) or an obstacle file in M. Otte's format.  Every obstacle is grown by the
robot radius R (:func:`grow_polygon`, a polygon that contains the exact Minkowski
sum with the disc).  RRT^X plans on the grown polygons for 85 % of ``--time``
seconds of wall time; in the rest, the tree path and graph paths through other
corridors of the RRT^X graph (:func:`candidate_routes`) are shortened by
:class:`rrtq_planner.shortcut.Shortener` and the shortest is returned.
One JSON line is printed::

    {"path": [[x, y], ...], "cost": ..., "rrtx_cost": ..., "nodes": ..., "iterations": ...,
     "time_s": ...}

``cost`` is the length (m) of the returned path, ``rrtx_cost`` that of the raw tree
path, ``time_s`` the wall time of planning plus post-processing.

Exit codes: 0 path found; 1 no path (``"path": []``, ``"cost": null``); 2 bad input
(the file or argument is named on stderr).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from shapely.geometry import Polygon

from .geometry import ObstacleMap
from .rrtx import RRTX, PlanStatus, RRTXConfig
from .safety import grow_polygon
from .shortcut import Shortener, path_length

EXIT_OK = 0
EXIT_NO_PATH = 1
EXIT_BAD_INPUT = 2

# m added to R when growing: the grown polygons only touch the disc-grown set at
# tangent points, so a path brushing one would sit at R minus rounding error.
CLEARANCE_SLACK = 1e-6
# m added around an Otte environment's bounding box, beyond R.
OTTE_PADDING = 1.0
# RRT^X iterations between two looks at the clock.
_CHUNK = 25
# Sides of the polygon that stands in for the disc at each obstacle corner.
DISC_SIDES = 32
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


class BadInput(Exception):
    """Unusable input; the message names the file or the argument."""


@dataclass(frozen=True)
class Environment:
    """Obstacles and limits read from ENV.

    Attributes
    ----------
    polygons : tuple of numpy.ndarray
        Original (not grown) obstacle polygons (k, 2), m.
    bounds : tuple of float or None
        (x_min, x_max, y_min, y_max), m; None when the file has none (Otte).
    robot_radius : float or None
        m; None when the file has none (Otte).
    """

    polygons: tuple[np.ndarray, ...]
    bounds: tuple[float, float, float, float] | None
    robot_radius: float | None


def load_environment(path: str) -> Environment:
    """Read a scenario YAML (``.yaml``/``.yml``) or an Otte obstacle file.

    Otte flags: 0 (known) and 1 (unknown until sensed) are obstacles that exist;
    -1 (believed but absent) does not exist and is skipped.

    Raises
    ------
    BadInput
        Unreadable or malformed file (the message names it).
    """
    if not os.path.isfile(path):
        raise BadInput(f'{path}: no such file')
    if path.lower().endswith(('.yaml', '.yml')):
        from rrtq_sim.scenario import ScenarioError, load_scenario
        try:
            scenario = load_scenario(path)
        except ScenarioError as exc:
            raise BadInput(str(exc)) from None
        (x0, x1), (y0, y1) = scenario.bounds
        polys = tuple(np.asarray(s.polygon, dtype=float) for s in scenario.obstacles
                      if s.exists(0.0))
        return Environment(polys, (x0, x1, y0, y1), float(scenario.robot_radius))
    from rrtq_sim.obstacles import load_otte
    try:
        entries = load_otte(path)
    except OSError as exc:
        raise BadInput(f'{path}: cannot read: {exc.strerror or exc}') from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadInput(f'{path}: not an Otte obstacle file: {exc}') from None
    return Environment(tuple(np.asarray(p, dtype=float) for p, flag in entries if flag != -1),
                       None, None)


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


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'expected a finite number, got {text!r}')
    return value


def _positive(text: str) -> float:
    value = _finite(text)
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f'must be > 0, got {text}')
    return value


def _nonnegative(text: str) -> float:
    value = _finite(text)
    if value < 0.0:
        raise argparse.ArgumentTypeError(f'must be >= 0, got {text}')
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be >= 0, got {text}')
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``rrtq plan``."""
    parser = argparse.ArgumentParser(
        prog='rrtq plan',
        description='Plan with RRT^X on a scenario or an Otte obstacle file; print JSON.')
    parser.add_argument('env', metavar='ENV', help='scenario YAML or Otte obstacle file')
    parser.add_argument('--start', nargs=2, type=_finite, required=True, metavar=('X', 'Y'),
                        help='start position (m)')
    parser.add_argument('--goal', nargs=2, type=_finite, required=True, metavar=('X', 'Y'),
                        help='goal position (m)')
    parser.add_argument('--time', type=_positive, default=2.0, metavar='S',
                        help='wall-time budget (s) for RRT^X and shortening (default 2)')
    parser.add_argument('--radius', type=_nonnegative, metavar='R',
                        help="robot radius (m) obstacles are grown by (default: the "
                             "scenario's robot_radius; 0 for an Otte file)")
    parser.add_argument('--seed', type=_seed, default=0, help='random seed (default 0)')
    parser.add_argument('--bounds', nargs=4, type=_finite,
                        metavar=('XMIN', 'XMAX', 'YMIN', 'YMAX'),
                        help="sampling region (m) (default: the scenario's bounds; for an "
                             'Otte file the box of obstacles, start and goal padded by R + 1)')
    return parser


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


def check_point(name: str, point: np.ndarray, bounds: tuple[float, float, float, float],
                grown: ObstacleMap) -> None:
    """Raise BadInput when ``point`` is outside ``bounds`` or inside a grown obstacle."""
    x0, x1, y0, y1 = bounds
    if not (x0 <= point[0] <= x1 and y0 <= point[1] <= y1):
        raise BadInput(f'{name} {point.tolist()} is outside the bounds '
                       f'x [{x0:g}, {x1:g}], y [{y0:g}, {y1:g}]')
    for oid in grown.ids():
        probe = ObstacleMap()
        probe.add(oid, grown.polygon(oid))
        if not probe.point_free(point):
            raise BadInput(f'{name} {point.tolist()} is inside obstacle {oid} grown by the '
                           'robot radius')


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
    ``deadline`` (a ``time.perf_counter()`` value) passes.
    """
    best: np.ndarray | None = None
    for route in candidate_routes(planner, start):
        if best is not None and time.perf_counter() >= deadline:
            break
        if len(route) == 1:  # the robot sits on the goal
            route = np.vstack((route, route))
        short = shortener.simplify(route)
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


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``rrtq plan`` with ``argv`` (the arguments after ``plan``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(None if argv is None else list(argv))
    except SystemExit as exc:  # argparse has printed usage and the error
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    try:
        env = load_environment(args.env)
        start = np.array(args.start, dtype=float)
        goal = np.array(args.goal, dtype=float)
        radius = args.radius if args.radius is not None else (env.robot_radius or 0.0)
        if args.bounds is not None:
            x0, x1, y0, y1 = args.bounds
            if not (x0 < x1 and y0 < y1):
                raise BadInput(f'--bounds: expected XMIN < XMAX and YMIN < YMAX, got '
                               f'{args.bounds}')
            bounds = (x0, x1, y0, y1)
        elif env.bounds is not None:
            bounds = env.bounds
        else:
            bounds = default_bounds(env.polygons, start, goal, radius)
        obstacles = ObstacleMap()
        for i, poly in enumerate(grow(env.polygons, radius)):
            obstacles.add(f'{i}', poly)
        check_point('--start', start, bounds, obstacles)
        check_point('--goal', goal, bounds, obstacles)
    except BadInput as exc:
        print(f'rrtq plan: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    result = plan(env.polygons, start, goal, bounds, radius, args.time, args.seed)
    print(result.to_json())
    return EXIT_OK if result.cost is not None else EXIT_NO_PATH


if __name__ == '__main__':
    sys.exit(main())
