"""``rrtq plan ENV --start X Y --goal X Y``: the planner alone, as a command.

ENV is a scenario YAML (its obstacles that exist at t = 0, its bounds, its robot
radius) or an obstacle file in M. Otte's format; the planning is
:func:`rrtq_planner.routes.plan`. One JSON line is printed::

    {"path": [[x, y], ...], "cost": ..., "rrtx_cost": ..., "nodes": ..., "iterations": ...,
     "time_s": ...}

``cost`` is the length (m) of the returned path, ``rrtx_cost`` that of the raw tree
path, ``time_s`` the wall time of planning plus post-processing.

Exit codes: 0 path found; 1 no path (``"path": []``, ``"cost": null``); 2 bad input
(the file or argument is named on stderr).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rrtq_bringup.scenario import ScenarioError, load_scenario
from rrtq_common.otte import load_otte
from rrtq_planner.geometry import ObstacleMap
from rrtq_planner.routes import default_bounds, grow, plan

EXIT_OK = 0
EXIT_NO_PATH = 1
EXIT_BAD_INPUT = 2


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
        try:
            scenario = load_scenario(path)
        except ScenarioError as exc:
            raise BadInput(str(exc)) from None
        (x0, x1), (y0, y1) = scenario.bounds
        polys = tuple(np.asarray(s.polygon, dtype=float) for s in scenario.obstacles
                      if s.exists(0.0))
        return Environment(polys, (x0, x1, y0, y1), float(scenario.robot_radius))
    try:
        entries = load_otte(path)
    except OSError as exc:
        raise BadInput(f'{path}: cannot read: {exc.strerror or exc}') from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadInput(f'{path}: not an Otte obstacle file: {exc}') from None
    return Environment(tuple(np.asarray(p, dtype=float) for p, flag in entries if flag != -1),
                       None, None)


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
