"""Configuration and outcome types of the RRT^X core."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from rrtq_common.settings import check, setting

FILL_FRACTION = 0.5
"""Past ``max_nodes``, a sample is kept only this fraction of r(n) or farther from every node."""


class PlanStatus(enum.Enum):
    """What the planner can currently offer the robot."""

    SEARCHING = "searching"
    """The robot's position has not joined the tree yet."""
    FOUND = "found"
    """A collision-free path from the robot to the goal is known."""
    NO_PATH = "no_path"
    """The robot was connected, but obstacles cut it off from the goal."""


@dataclass(frozen=True)
class RRTXConfig:
    """Parameters of RRT^X in 2D position space (Otte & Frazzoli, IJRR 2016).

    Attributes
    ----------
    goal : tuple[float, float]
        Goal position (m); the root of the tree.
    bounds : tuple[float, float, float, float]
        Sampling region (x_min, x_max, y_min, y_max) in m.
    steer_distance : float
        delta (m): samples farther than this from the tree are saturated
        towards their nearest node, and r(n) never exceeds it.
    epsilon : float
        epsilon (m): the consistency tolerance; lmc decreases of at most
        epsilon are not propagated.  0 gives exact shortest paths on the graph.
    ball_constant : float or None
        gamma (m) of r(n) = min(gamma (log n / n)^(1/2), delta).  None derives
        it from ``free_space_measure``: 10 % above the paper's lower bound
        2 (1 + 1/d)^(1/d) (mu(X_free) / zeta_d)^(1/d) with d = 2.
    free_space_measure : float or None
        mu(X_free) in m^2; None uses the area of ``bounds`` (an upper bound,
        which only enlarges the ball).
    robot_radius : float
        m.  The nodes keep this distance from the border of ``bounds`` (the
        region's first margin, until ``update_obstacles`` gives another: see
        :class:`rrtq_planner.bounds.Region`).  Obstacle polygons are expected
        already grown by it.
    robot_sample_probability : float
        Probability (0..1) that an iteration samples the robot's position
        while the robot has not yet joined the tree.
    reach_tolerance : float
        m.  ``set_robot`` moves v_bot on to its parent once the robot is this
        close to v_bot.
    stall_time, stall_progress : float
        s, m.  ``set_robot`` with a time also moves v_bot on to its parent when
        the robot has come no closer to v_bot by ``stall_progress`` for
        ``stall_time`` and sees the parent along a free segment: a waypoint the
        controller cannot reach (an optimal policy held 1.6 m off one by a
        lateral gust, its spring balancing the push) would otherwise keep the
        robot there for good.
    max_nodes : int or None
        Beyond this many nodes the graph stops getting denser: a sample is
        kept only where no node lies within ``FILL_FRACTION`` r(n), so the
        graph still covers space it has not reached, or that a vanished
        obstacle freed (nodes are never placed inside an obstacle), at a
        bounded size.  None: no limit.
    path_bias : float
        Probability p in [0, 0.9] that an iteration, once a path is known,
        samples about it instead of uniformly: about an interior vertex of the
        current path drawn with probability proportional to its turning angle
        (where the path bends round an obstacle, and where it is furthest from
        the optimum), displaced by a Gaussian of standard deviation r(n) / 2
        in each axis.  The uniform samples alone, about (1 - p) n of them,
        then need the ball gamma (log n_u / n_u)^(1/2) <= gamma (1 - p)^(-1/2)
        (log n / n)^(1/2) for the asymptotic optimality argument, so gamma is
        scaled by (1 - p)^(-1/2); the biased nodes only add vertices and edges.
        The path's bends get denser, and the raw path converges sooner.
        0 (the default): uniform sampling, as in the paper.
    """

    goal: tuple[float, float] = setting(unit="m", doc="goal position, the root of the tree")
    bounds: tuple[float, float, float, float] = setting(
        unit="m", doc="sampling region x_min x_max y_min y_max")
    steer_distance: float = setting(5.0, unit="m", low=0.0, low_open=True,
                                    doc="RRT^X steer distance delta")
    epsilon: float = setting(0.0, unit="m", low=0.0, doc="RRT^X epsilon-consistency")
    ball_constant: float | None = setting(None, unit="m", low=0.0, low_open=True,
                                          doc="gamma of r(n); None: from the free space")
    free_space_measure: float | None = setting(None, unit="m^2", low=0.0, low_open=True,
                                               doc="mu(X_free); None: the area of bounds")
    robot_radius: float = setting(0.0, unit="m", low=0.0,
                                  doc="samples keep this distance from the border")
    robot_sample_probability: float = setting(0.05, low=0.0, high=1.0,
                                              doc="chance an iteration samples the robot")
    reach_tolerance: float = setting(1e-3, unit="m", low=0.0,
                                     doc="v_bot moves on to its parent this close")
    stall_time: float = setting(10.0, unit="s", low=0.0, low_open=True,
                                doc="v_bot also moves on to a parent the robot sees when the "
                                "robot has come no closer to v_bot for this long; inf: never")
    stall_progress: float = setting(0.1, unit="m", low=0.0,
                                    doc="coming this much closer to v_bot is progress")
    max_nodes: int | None = setting(None, low=2, doc="past this size the graph only fills "
                                    "gaps; None: no limit")
    path_bias: float = setting(0.0, low=0.0, high=0.9, doc="share of samples about the "
                               "current path's bends once one is known; 0: uniform")

    def __post_init__(self) -> None:
        check(self)
        x0, x1, y0, y1 = self.bounds
        if not (x1 - x0 > 2 * self.robot_radius and y1 - y0 > 2 * self.robot_radius):
            raise ValueError("bounds must be non-empty after shrinking by robot_radius")

    @property
    def gamma(self) -> float:
        """The ball constant gamma in m (given or derived), scaled for ``path_bias``."""
        scale = 1.0 / math.sqrt(1.0 - self.path_bias)
        if self.ball_constant is not None:
            return self.ball_constant * scale
        x0, x1, y0, y1 = self.bounds
        mu = self.free_space_measure or (x1 - x0) * (y1 - y0)
        return scale * 1.1 * 2.0 * math.sqrt(1.5) * math.sqrt(mu / math.pi)

    def ball_radius(self, n: int) -> float:
        """r(n) = min(gamma (log n / n)^(1/2), delta) in m (paper, eq. 1)."""
        if n < 2:
            return self.steer_distance
        return min(self.gamma * math.sqrt(math.log(n) / n), self.steer_distance)
