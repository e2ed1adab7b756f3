"""Random obstacle layouts for the Monte Carlo bench, one per seed (no ROS).

A layout replaces the base scenario's obstacles with

- *known* obstacles, in the robot's map from t = 0, scattered about the straight line
  from the start to the goal;
- *appearing* obstacles, unknown, placed about the shortest route through the known
  ones (the route the robot is likely to take) and timed to appear while the robot is
  expected to be within perception range of them: an obstacle at distance s along the
  route appears when a robot progressing at ``speed`` would be ``u`` perception radii
  short of it, u uniform in ``lead``.

No obstacle comes within ``end_clearance`` of the robot's disc at the start or the goal,
and the goal stays reachable with every obstacle present at once (checked on the
visibility graph, :mod:`rrtq_common.optimum`; otherwise the layout is drawn
again). Where the robot really is when an obstacle appears is not known here: the
simulator holds back one that would appear on the robot (``appear_clearance``,
:class:`rrtq_sim.perception.TrueObstacles`). Everything follows from the seed.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any

import numpy as np

from rrtq_bringup.scenario import Scenario
from rrtq_common.geometry import point_polygon_distance, polygon_from_circle
from rrtq_common.optimum import Optimum, shortest_path

__all__ = ['LayoutConfig', 'Layout', 'LayoutError', 'generate_layout', 'layout_scenario']

# Mixed into the seed so that the layout's stream differs from the run's generators.
_STREAM = 0x4C41594F5554


class LayoutError(Exception):
    """No acceptable layout within the allowed attempts."""


@dataclasses.dataclass(frozen=True)
class LayoutConfig:
    """How layouts are drawn.

    Attributes
    ----------
    obstacles : int
        Obstacles per layout (>= 0).
    known_fraction : float
        Share of them known from t = 0, in [0, 1] (rounded down).
    size : (float, float)
        Range of rectangle sides and circle diameters, m.
    spread : float
        Standard deviation of the known obstacles' offset from the start-goal line, m.
    route_offset : float
        Standard deviation of the appearing obstacles' offset from the route, m.
    end_clearance : float
        Smallest gap between the robot's disc at the start or goal and an obstacle, m.
    speed : float
        Assumed progress of the robot along the route, m/s (sets the appear times).
    lead : (float, float)
        Range of the robot's expected distance short of an obstacle when it appears,
        in perception radii.
    earliest : float
        Earliest appear time, s (> 0: it appears during the run).
    attempts : int
        Layouts drawn before giving up.
    """

    obstacles: int = 8
    known_fraction: float = 0.25
    size: tuple[float, float] = (1.5, 6.0)
    spread: float = 4.0
    route_offset: float = 1.0
    end_clearance: float = 2.0
    speed: float = 0.65
    lead: tuple[float, float] = (0.25, 1.0)
    earliest: float = 1.0
    attempts: int = 200

    def __post_init__(self) -> None:
        if self.obstacles < 0:
            raise ValueError(f'obstacles must be >= 0, got {self.obstacles}')
        if not 0.0 <= self.known_fraction <= 1.0:
            raise ValueError(f'known_fraction must be in [0, 1], got {self.known_fraction}')
        if not 0.0 < self.size[0] <= self.size[1]:
            raise ValueError(f'size must be 0 < low <= high, got {self.size}')
        if not (self.speed > 0.0 and self.earliest > 0.0 and self.attempts >= 1):
            raise ValueError('speed, earliest and attempts must be positive')


@dataclasses.dataclass(frozen=True, eq=False)
class Layout:
    """One seed's obstacles.

    Attributes
    ----------
    seed : int
    obstacles : tuple of dict
        Scenario-file entries (``id``, ``polygon`` or ``circle``, ``known``, ``appear_at``).
    optimum : Optimum
        Shortest path with every obstacle present, for the robot's disc.
    route : Optimum
        Shortest path through the known obstacles alone.
    attempts : int
        Layouts drawn to find this one.
    """

    seed: int
    obstacles: tuple[dict[str, Any], ...]
    optimum: Optimum
    route: Optimum
    attempts: int


def _shape(rng: np.random.Generator, centre: np.ndarray, size: tuple[float, float],
           ident: str) -> tuple[dict[str, Any], np.ndarray]:
    """A rotated rectangle or a circle about ``centre``: its entry and its polygon."""
    c = np.round(centre, 3)
    if rng.random() < 0.5:
        radius = round(float(rng.uniform(*size)) / 2.0, 3)
        entry = {'id': ident, 'circle': {'center': c.tolist(), 'radius': radius}}
        return entry, polygon_from_circle(c, radius)
    half = rng.uniform(*size, 2) / 2.0
    angle = rng.uniform(0.0, math.pi)
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    poly = np.round(c + corners @ rot.T, 3)
    return {'id': ident, 'polygon': poly.tolist()}, poly


def _along(path: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray]:
    """Point at arc length ``s`` along a polyline and the unit normal there."""
    seg = np.diff(path, axis=0)
    lengths = np.hypot(seg[:, 0], seg[:, 1])
    k = int(np.searchsorted(np.cumsum(lengths), s, side='right'))
    k = min(k, len(seg) - 1)
    into = s - float(np.sum(lengths[:k]))
    tangent = seg[k] / lengths[k]
    return path[k] + into * tangent, np.array([-tangent[1], tangent[0]])


def _draw(rng: np.random.Generator, scenario: Scenario, config: LayoutConfig
          ) -> tuple[list[dict[str, Any]], list[np.ndarray], Optimum]:
    """One candidate layout (entries, polygons, the known route); may be unreachable."""
    start, goal = np.asarray(scenario.start), np.asarray(scenario.goal)
    (x0, x1), (y0, y1) = scenario.bounds
    keep_off = scenario.robot_radius + config.end_clearance

    def acceptable(centre: np.ndarray, poly: np.ndarray) -> bool:
        inside = x0 < centre[0] < x1 and y0 < centre[1] < y1
        return inside and bool(np.all(point_polygon_distance(np.stack((start, goal)), poly)
                                      > keep_off))

    def place(ident: str, draw_centre) -> tuple[dict[str, Any], np.ndarray, float] | None:
        """Draw ``(centre, s)`` and a shape there until it keeps off the start and goal."""
        for _ in range(100):
            centre, s = draw_centre()
            entry, poly = _shape(rng, centre, config.size, ident)
            if acceptable(centre, poly):
                return entry, poly, s
        return None

    entries: list[dict[str, Any]] = []
    polygons: list[np.ndarray] = []
    n_known = int(config.obstacles * config.known_fraction)
    line = goal - start
    normal = np.array([-line[1], line[0]]) / max(float(np.hypot(*line)), 1e-12)

    def near_line() -> tuple[np.ndarray, float]:
        return (start + rng.uniform(0.1, 0.9) * line
                + rng.normal(0.0, config.spread) * normal), 0.0

    for k in range(n_known):
        placed = place(f'known_{k}', near_line)
        if placed is not None:
            placed[0]['known'] = True
            entries.append(placed[0])
            polygons.append(placed[1])
    route = shortest_path(polygons, start, goal, scenario.robot_radius, scenario.bounds)
    if not route.reachable:
        return entries, polygons, route

    def near_route() -> tuple[np.ndarray, float]:
        s = float(rng.uniform(0.0, route.length))
        point, side = _along(route.path, s)
        return point + rng.normal(0.0, config.route_offset) * side, s

    for k in range(config.obstacles - n_known):
        placed = place(f'appear_{k}', near_route)
        if placed is None:
            continue
        robot_s = placed[2] - rng.uniform(*config.lead) * scenario.perception_radius
        placed[0]['appear_at'] = round(float(max(config.earliest, robot_s / config.speed)), 2)
        entries.append(placed[0])
        polygons.append(placed[1])
    return entries, polygons, route


def generate_layout(scenario: Scenario, seed: int, config: LayoutConfig = LayoutConfig()
                    ) -> Layout:
    """The layout of ``seed`` for the scenario's bounds, start, goal and robot.

    Raises
    ------
    LayoutError
        When no reachable layout is found in ``config.attempts`` draws.
    """
    rng = np.random.default_rng([_STREAM, seed])
    start, goal = np.asarray(scenario.start), np.asarray(scenario.goal)
    for attempt in range(1, config.attempts + 1):
        entries, polygons, route = _draw(rng, scenario, config)
        if not route.reachable:
            continue
        optimum = shortest_path(polygons, start, goal, scenario.robot_radius, scenario.bounds)
        if optimum.reachable:
            return Layout(seed, tuple(entries), optimum, route, attempt)
    raise LayoutError(f'{scenario.path}: no layout with a reachable goal in {config.attempts} '
                      f'draws (seed {seed}); fewer or smaller obstacles may do')


def layout_scenario(document: dict[str, Any], layout: Layout, name: str,
                    keep: bool = False) -> dict[str, Any]:
    """The base scenario document with the layout's obstacles, the seed and a run name.

    ``keep``: the base's own obstacles stay, the layout's are added to them.
    """
    out = copy.deepcopy(document)
    out['name'] = name
    out['seed'] = layout.seed
    kept = list(out.get('obstacles') or []) if keep else []
    out['obstacles'] = kept + [copy.deepcopy(e) for e in layout.obstacles]
    return out
