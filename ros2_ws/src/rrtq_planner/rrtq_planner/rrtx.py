"""RRT^X: asymptotically optimal single-query planning with quick replanning.

Otte & Frazzoli, "RRTX: Asymptotically optimal single-query sampling-based
motion planning with quick replanning", IJRR 35(7), 2016.  Algorithm numbers
below refer to that paper.  The tree is rooted at the goal; g is the
cost-to-goal, lmc its one-step look-ahead; Q is keyed by (min(g, lmc), g).

The module splits along the paper's seams: this file samples and extends
(Algorithms 1, 2, 6); ``rrtx_rewire`` culls, rewires and reduces the
inconsistency (Algorithms 3-5, 12, 13); ``rrtx_obstacles`` handles obstacle
changes (Algorithms 7-11); ``rrtx_robot`` moves v_bot and reads out the path.

Deliberate deviations, each needed for a property the tests check:

* ``cull_neighbors`` compares the geometric edge length with r(n), not the
  cost (which is inf while blocked): blocked running edges survive culling
  and ``remove_obstacle`` restores them (the reference code loses them).
  Culling removes both halves of an edge, so out- and in-lists stay mirrors.
* Culling during update_lmc / rewire waits until a running edge exceeds
  1.05 r(n); r(n) shrinks at every insertion, and trimming lists by one edge
  at a time cost more than the few extra neighbours.
* When the ball around a sample is empty, the nearest node alone is used
  (as the reference code does); otherwise a sample steered to distance
  delta > r(n) could never join.
* A new node gets g = lmc right after its rewiring (the reference queues it,
  which only repeats the same rewiring when it is popped).
* ``remove_obstacle`` queues a node when g - lmc > epsilon (the paper: g != lmc),
  and a popped v_bot with g != lmc is always rewired.  Then every node outside
  Q satisfies lmc(u) <= d(u, w) + g(w) for each edge u -> w, which gives the
  bound proved in ``reduce_inconsistency``.
* ``max_nodes`` (not in the paper) bounds the graph without freezing it:
  past it a sample is kept only in a gap (no node within r(n) / 2), so
  space an obstacle freed when it vanished still gets nodes and paths.
* ``propagate_descendants`` re-roots all orphans with one Dijkstra search
  (scipy) instead of queueing their neighbours with g = inf and popping them
  one by one; see its docstring for why the result is the same.
* ``set_robot`` with a time also moves v_bot on to its parent when the robot
  has stalled short of v_bot (``stall_time``, ``stall_progress``) and sees the
  parent along a free segment: the paper's robot reaches every node it is
  sent to, ours may not (a gust its controller's gain cannot overcome).
* The free space is bounded by a region, the bounds shrunk by a margin
  (``robot_radius`` at first, then the margin ``update_obstacles`` is given:
  the one the obstacles are grown by): samples, steered points and the
  robot's join point lie in it, and a parent search takes only nodes in it
  (the goal always).  The region is convex, so every edge between two of its
  points lies in it without a test; a margin that moves blocks and restores
  edges as an obstacle does (``rrtx_obstacles``), and a robot outside it is
  handled in ``rrtx_robot``.
"""

from __future__ import annotations

import numpy as np

from .bounds import Region
from .geometry import ObstacleMap
from .graph import INF, RRTXGraph
from .heap import KeyedQueue
from .neighbors import PointIndex
from .rrtx_config import FILL_FRACTION, PlanStatus, RRTXConfig
from .rrtx_obstacles import ObstacleMixin
from .rrtx_rewire import RewireMixin
from .rrtx_robot import RobotMixin

__all__ = ["RRTX", "RRTXConfig", "PlanStatus"]

_BATCH = 512
# path_bias: a bend's weight is its turning angle (rad) plus this floor, so a
# straight stretch still gets samples; the samples spread this many r(n) about it.
_BEND_FLOOR = 1e-3
_BEND_SPREAD = 0.5


class RRTX(RewireMixin, ObstacleMixin, RobotMixin):
    """The RRT^X planner core (numpy/scipy only, deterministic given ``rng``).

    Parameters
    ----------
    config : RRTXConfig
        Planner parameters.
    rng : numpy.random.Generator
        The only source of randomness (drawn in batches of 512 samples).

    Examples
    --------
    >>> cfg = RRTXConfig(goal=(0.0, -40.0), bounds=(-50.0, 50.0, -50.0, 50.0))
    >>> planner = RRTX(cfg, np.random.default_rng(0))
    >>> wall = np.array([[-5.0, -1.0], [5.0, -1.0], [5.0, 1.0], [-5.0, 1.0]])
    >>> planner.add_obstacle("wall", wall)
    >>> planner.set_robot((0.0, 40.0))
    >>> planner.run(2000)
    >>> planner.status
    <PlanStatus.FOUND: 'found'>
    >>> waypoints = planner.path()  # (N, 2): robot, v_bot, ..., goal
    """

    def __init__(self, config: RRTXConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._eps = config.epsilon
        self.graph = RRTXGraph()
        self.queue = KeyedQueue()
        self.index = PointIndex()
        self.obstacles = ObstacleMap()
        self._blocked_by: dict[str, np.ndarray] = {}
        self._orphans: list[int] = []
        goal = np.asarray(config.goal, dtype=float)
        self.goal = self.graph.add_node(goal)
        self.index.insert(goal)
        self.graph.g[self.goal] = 0.0
        self.graph.lmc[self.goal] = 0.0
        self.region = Region(config.bounds, config.robot_radius)
        self._region_blocked = np.zeros(0, dtype=np.intp)
        self._samples = np.zeros((0, 3))
        self._next = 0
        self.radius = config.ball_radius(1)
        self.iterations = 0
        self._bias_cost = INF       # the path that path_bias samples about, when cached
        self._bias_path = np.zeros((0, 2))
        self._bias_length = 0.0
        self._bias_cdf = np.ones(1)
        self._init_robot()

    # ------------------------------------------------------------ sampling
    @property
    def node_count(self) -> int:
        """Number of nodes |V| (the goal included)."""
        return self.graph.n

    def _draw(self) -> np.ndarray:
        if self._next == self._samples.shape[0]:
            self._samples = self._rng.random((_BATCH, 3))
            self._next = 0
        row: np.ndarray = self._samples[self._next]
        self._next += 1
        return row

    def run(self, iterations: int) -> None:
        """Run ``iterations`` sampling iterations (the main loop of Algorithm 1)."""
        for _ in range(iterations):
            self.step()

    def step(self) -> int | None:
        """One iteration of Algorithm 1: sample, extend, rewire, reduce.

        Returns
        -------
        int or None
            The new node's index, or None when the sample was rejected.
        """
        self.iterations += 1
        cfg = self.config
        self.radius = cfg.ball_radius(self.graph.n)
        row = self._draw()
        robot = self.robot
        is_robot = (
            self.vbot < 0 and robot is not None and row[2] < cfg.robot_sample_probability
        )
        region = self.region
        if is_robot and robot is not None:
            point = region.clamp(robot)     # outside the region: its nearest point (join)
        elif self.vbot >= 0 and row[2] < cfg.path_bias and self._path_length() > 0.0:
            point = self._sample_about_path()
        else:
            point = region.lo + region.span * row[:2]
        nearest, dist, near = self.index.nearest_and_near(point, self.radius)
        if dist == 0.0:
            if is_robot:
                self._attach_robot(nearest)
            return None
        if dist > cfg.steer_distance:
            # Saturate towards the nearest node (Algorithm 1).
            base = self.graph.pos[nearest]
            point = base + (point - base) * (cfg.steer_distance / dist)
            # Between two points of the (convex) region; the clip only undoes rounding.
            point = np.clip(point, region.lo, region.hi)
            is_robot = False
            nearest, dist, near = self.index.nearest_and_near(point, self.radius)
        if (not is_robot and cfg.max_nodes is not None and self.graph.n >= cfg.max_nodes
                and dist < FILL_FRACTION * self.radius):
            return None  # the graph is full here; past max_nodes it only fills gaps
        if not self.obstacles.point_free(point):
            return None
        v = self.extend(point, near)
        if v is None:
            return None
        self.rewire_neighbors(v)
        self.graph.g[v] = self.graph.lmc[v]
        if is_robot:
            self._attach_robot(v)
        self.reduce_inconsistency()
        return v

    def _path_length(self) -> float:
        """Length (m) of the current path; caches it and its bend weights."""
        cost = self.cost()
        if cost != self._bias_cost:
            self._bias_cost = cost
            path = self.path()
            self._bias_path = path
            self._bias_length = 0.0
            if path.shape[0] >= 2:
                seg = np.diff(path, axis=0)
                self._bias_length = float(np.hypot(seg[:, 0], seg[:, 1]).sum())
                heading = np.arctan2(seg[:, 1], seg[:, 0])
                turn = np.abs((np.diff(heading) + np.pi) % (2.0 * np.pi) - np.pi)
                weight = turn + _BEND_FLOOR
                self._bias_cdf = np.cumsum(weight) / weight.sum()
        return self._bias_length

    def _sample_about_path(self) -> np.ndarray:
        """A sample about a bend of the current path (``path_bias``, see RRTXConfig)."""
        path = self._bias_path
        u, dx, dy = self._rng.random(), self._rng.normal(), self._rng.normal()
        if path.shape[0] < 3:
            centre = path[0] + u * (path[-1] - path[0])
        else:
            k = min(int(np.searchsorted(self._bias_cdf, u)), self._bias_cdf.shape[0] - 1)
            centre = path[k + 1]
        point = centre + _BEND_SPREAD * self.radius * np.array((dx, dy))
        return np.clip(point, self.region.lo, self.region.hi)

    # ------------------------------------------------------- tree building
    def extend(self, point: np.ndarray, near: np.ndarray) -> int | None:
        """Algorithm 2: insert ``point`` if it can reach the tree.

        The new node gets its parent from ``find_parent`` and an edge to every
        near node with a free segment (the straight segment is free in both
        directions or in neither, so both directions are created).

        Parameters
        ----------
        point : numpy.ndarray
            Collision-free sample, shape (2,), metres.
        near : numpy.ndarray
            Node indices within the ball r(n) (or the nearest node alone).

        Returns
        -------
        int or None
            The new node, or None when no near node offers a finite cost.
        """
        near, lengths, j = self.find_parent(point, near)
        if j < 0:
            return None
        gr = self.graph
        v = gr.add_node(point)
        self.index.insert(point)
        gr.lmc[v] = lengths[j] + gr.lmc[near[j]]
        gr.make_parent_of(int(near[j]), v)
        gr.add_edges(v, near, lengths)
        return v

    def find_parent(
        self, point: np.ndarray, near: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """Algorithm 6: the near node u minimising d(v, u) + lmc(u).

        Returns
        -------
        near : numpy.ndarray
            The near nodes with a collision-free segment to ``point``.
        lengths : numpy.ndarray
            Their distances to ``point`` (m).
        best : int
            Index into ``near`` of the parent, or -1 when none has finite cost.
        """
        gr = self.graph
        ends = gr.pos[near]
        # ``point`` is in the region, which is convex: a segment to a node in it stays in it.
        free = self.obstacles.segments_free_from(point, ends, start_free=True)
        free &= self.region.contains(ends) | (near == self.goal)
        if not free.all():
            near = near[free]
            ends = ends[free]
        if near.shape[0] == 0:
            return near, np.zeros(0), -1
        diff = ends - point
        lengths = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        costs = lengths + gr.lmc[near]
        j = int(costs.argmin())
        return near, lengths, (j if costs[j] < INF else -1)

    # ------------------------------------------------------------ results
    def edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All directed edges (tail, head, current cost in m; inf if blocked)."""
        return self.graph.directed_edges()

    def neighbors(self, v: int) -> dict[str, list[int]]:
        """N0+, N0-, Nr+, Nr- of v as sorted node lists."""
        return self.graph.neighbor_lists(v)

    @property
    def g(self) -> np.ndarray:
        """Copy of g (m) for all nodes."""
        return self.graph.g[: self.graph.n].copy()

    @property
    def lmc(self) -> np.ndarray:
        """Copy of lmc (m) for all nodes."""
        return self.graph.lmc[: self.graph.n].copy()

    @property
    def parents(self) -> np.ndarray:
        """Copy of the parent pointers (-1: none)."""
        return self.graph.parent[: self.graph.n].copy()

    @property
    def positions(self) -> np.ndarray:
        """Copy of node positions (n, 2) in m."""
        return self.graph.pos[: self.graph.n].copy()

    def queue_contents(self) -> list[int]:
        """Nodes currently in Q."""
        return sorted(self.queue.nodes())
