"""The robot side of RRT^X: v_bot, its edge, the path and its cost.

The robot is not a tree node: it sits somewhere on the edge towards v_bot,
"the next node on its current edge" (Otte & Frazzoli 2016, and the
reference code's ``moveRobot`` / ``findNewTarget``).  The reported cost is
g(v_bot) plus the straight distance from the robot to v_bot.

The robot itself may be outside the region (the bounds shrunk by the margin,
where every node lies): its own segment to v_bot is checked against the
obstacles only, so a robot the margin grew past, or a gust pushed toward a
wall, goes on from where it is.  Two cases join it through the nearest point
of the region instead (beyond the paper): joining the tree from outside the
region (the point inserted is that nearest point, so no node lies outside),
and finding itself outside the bounds altogether (blown out): once per such
excursion that point is inserted and made v_bot, so the plan leads back in by
the shortest way and then on.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .graph import INF
from .rrtx_config import PlanStatus

if TYPE_CHECKING:
    from .bounds import Region
    from .geometry import ObstacleMap
    from .graph import RRTXGraph
    from .neighbors import PointIndex
    from .rrtx_config import RRTXConfig


class RobotMixin:
    """v_bot bookkeeping shared by :class:`rrtq_planner.rrtx.RRTX`."""

    config: RRTXConfig
    graph: RRTXGraph
    index: PointIndex
    obstacles: ObstacleMap
    radius: float
    goal: int
    region: Region

    if TYPE_CHECKING:  # provided by RRTX / RewireMixin; declared for mypy only

        def extend(self, point: np.ndarray, near: np.ndarray) -> int | None: ...

        def rewire_neighbors(self, v: int) -> None: ...

        def reduce_inconsistency(self) -> None: ...

    def _init_robot(self) -> None:
        self.robot: np.ndarray | None = None
        self.vbot = -1
        self._robot_edge_free = False
        self._blown_out = False
        """The robot was outside the bounds at the last call and has been sent back in."""
        self._progress: tuple[int, float, float] | None = None
        """(v_bot, time s, distance m) when the robot last came closer to v_bot."""

    def set_robot(self, position: np.ndarray, t: float | None = None) -> None:
        """Tell the planner where the robot is (m) at time ``t`` (s); moves v_bot along the tree.

        Before the robot has joined the tree it is inserted as a node as soon
        as it is within delta of the tree with a free segment.  Afterwards
        v_bot advances to its parent whenever the robot is within
        ``reach_tolerance`` of it, or has moved past it (a positive projection
        on the edge v_bot -> parent) and sees the parent along a free segment;
        if the segment robot -> v_bot is blocked or v_bot lost its path, a new
        target is searched for.  With ``t``, v_bot also advances to a parent the
        robot sees when the robot has stalled short of v_bot (``stall_time``,
        ``stall_progress``, counted only while v_bot has a path; beyond the paper).
        A robot outside the bounds is sent to the nearest point of the region
        (see the module notes).
        """
        p = np.array(position, dtype=float).reshape(2)
        self.robot = p
        if self.vbot < 0:
            self._connect_robot()
            return
        x0, x1, y0, y1 = self.config.bounds
        if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            if not self._blown_out:
                self._blown_out = True
                v = self._join(self.region.clamp(p))
                if v >= 0:
                    self._attach_robot(v)
                    return
        else:
            self._blown_out = False
        gr = self.graph
        tol2 = self.config.reach_tolerance**2
        v = self.vbot
        if not gr.g[v] < INF:
            # No path: the controller holds the robot by design (an empty plan), which is
            # not a stall; the clock starts again when a path is found.
            self._progress = None
        while v != self.goal and gr.parent[v] >= 0:
            nxt = int(gr.parent[v])
            off = p - gr.pos[v]
            reached = float(off @ off) <= tol2
            passed = float(off @ (gr.pos[nxt] - gr.pos[v])) > 0.0 and self._sees(nxt)
            if not (reached or passed or self._stalled(v, t) and self._sees(nxt)):
                break
            v = nxt
        self.vbot = v
        self._check_robot_target()

    def _sees(self, v: int) -> bool:
        """Whether the straight segment robot -> node v is free."""
        assert self.robot is not None
        return bool(self.obstacles.segments_free(self.robot.reshape(1, 2),
                                                 self.graph.pos[v].reshape(1, 2))[0])

    def _stalled(self, v: int, t: float | None) -> bool:
        """Whether the robot has come no closer to v by ``stall_progress`` for ``stall_time``."""
        if t is None or self.robot is None:
            return False
        dist = float(np.hypot(*(self.robot - self.graph.pos[v])))
        last = self._progress
        if last is None or last[0] != v or dist < last[2] - self.config.stall_progress:
            self._progress = (v, t, dist)
            return False
        return t - last[1] >= self.config.stall_time

    def _connect_robot(self) -> None:
        if self.robot is None:
            return
        v = self._join(self.region.clamp(self.robot))
        if v >= 0:
            self._attach_robot(v)

    def _join(self, p: np.ndarray) -> int:
        """The node at ``p`` (m, in the region), inserted if need be; -1 when it cannot join.

        It joins when it is within delta of the tree, free, and sees a node with a path.
        """
        nearest, dist, near = self.index.nearest_and_near(p, self.radius)
        if dist == 0.0:
            return nearest
        if dist > self.config.steer_distance or not self.obstacles.point_free(p):
            return -1
        v = self.extend(p, near)
        if v is None:
            return -1
        self.rewire_neighbors(v)
        self.graph.g[v] = self.graph.lmc[v]
        return v

    def _attach_robot(self, v: int) -> None:
        self.vbot = v
        self._check_robot_target()

    def _robot_edge_ok(self) -> bool:
        p = self.robot
        v = self.vbot
        if p is None or v < 0 or not self.graph.g[v] < INF:
            return False
        return bool(np.array_equal(p, self.graph.pos[v])) or self._sees(v)

    def _check_robot_target(self) -> None:
        """Settle v_bot and retarget when its edge became invalid."""
        if self.vbot < 0:
            return
        self.reduce_inconsistency()
        if not self._robot_edge_ok() and self.find_new_target():
            self.reduce_inconsistency()
        self._robot_edge_free = self._robot_edge_ok()

    def find_new_target(self) -> bool:
        """Pick the visible node minimising |robot - u| + lmc(u) as v_bot.

        The search ball starts at max(r(n), |robot - v_bot|) and doubles up to
        the diagonal of the bounds (the reference code's ``findNewTarget``).

        Returns
        -------
        bool
            True when a target with finite cost was found.
        """
        p = self.robot
        if p is None:
            return False
        gr = self.graph
        x0, x1, y0, y1 = self.config.bounds
        far = float(np.hypot(x1 - x0, y1 - y0)) + float(np.hypot(*(p - gr.pos[self.goal])))
        radius = max(self.radius, float(np.hypot(*(p - gr.pos[self.vbot]))), 1e-9)
        while True:
            idx = self.index.within(p, radius)
            idx = idx[gr.lmc[idx] < INF]
            if idx.shape[0]:
                ends = gr.pos[idx]
                free = self.obstacles.segments_free_from(p, ends)
                idx = idx[free]
                ends = ends[free]
                if idx.shape[0]:
                    cost = np.hypot(*(ends - p).T) + gr.lmc[idx]
                    self.vbot = int(idx[int(np.argmin(cost))])
                    return True
            if radius >= far:
                return False
            radius *= 2.0

    @property
    def robot_edge_free(self) -> bool:
        """Whether the straight segment robot -> v_bot was free at the last check."""
        return self._robot_edge_free

    def cost(self) -> float:
        """Path cost from the robot to the goal in m (inf without a path)."""
        if self.vbot < 0 or not self._robot_edge_free or self.robot is None:
            return INF
        v = self.vbot
        return float(self.graph.g[v] + np.hypot(*(self.robot - self.graph.pos[v])))

    @property
    def status(self) -> PlanStatus:
        """SEARCHING before the robot joined the tree, else FOUND / NO_PATH."""
        if self.vbot < 0:
            return PlanStatus.SEARCHING
        return PlanStatus.FOUND if self.cost() < INF else PlanStatus.NO_PATH

    def path(self) -> np.ndarray:
        """Waypoints (N, 2) in m: the robot, v_bot, its ancestors, the goal.

        Empty (0, 2) when there is no path.  The robot's own position is left
        out when it coincides with v_bot.
        """
        if self.cost() == INF or self.robot is None:
            return np.zeros((0, 2))
        gr = self.graph
        chain = [self.vbot]
        v = self.vbot
        while v != self.goal:
            v = int(gr.parent[v])
            if v < 0 or len(chain) > gr.n:
                raise RuntimeError("parent pointers do not lead to the goal")
            chain.append(v)
        pts = gr.pos[chain]
        if not np.array_equal(self.robot, pts[0]):
            pts = np.vstack((self.robot, pts))
        return pts
