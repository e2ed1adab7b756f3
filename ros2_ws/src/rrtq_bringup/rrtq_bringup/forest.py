"""Write a random discoverable forest scenario (YAML) to stdout or a file.

    python scenarios/envs/make_forest.py --seed 3 --out scenarios/forest_100.yaml

Trees are discs of random radius placed by rejection (dart throwing): every pair keeps
``--gap`` metres of free space between their trunks, so a corridor at least that wide
exists between any two trees, and none comes within ``--clear`` metres of the start or
the goal. All trees are unknown until sensed; a fraction ``--late`` of them physically
appear at a random time during the run. The plant, controller and perception are those
of ``scenarios/rrtqx_paper.yaml`` (the paper's rover, spring at the leg target).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

HEADER = """\
# A {size:g} x {size:g} m discoverable forest: {count} circular trees (radius {r_lo:g} to
# {r_hi:g} m, at least {gap:g} m of free space between trunks), all unknown until sensed
# within the {perception:g} m perception radius; {late} of them physically appear during
# the run. Start and goal at opposite corners. The paper's rover and controller
# (scenarios/rrtqx_paper.yaml). Written by scenarios/envs/make_forest.py --seed {seed}
# (regenerate rather than edit).
name: {name}
seed: {seed}
bounds: {{x: [0, {size:g}], y: [0, {size:g}]}}
start: [{start:g}, {start:g}]
goal: [{goal:g}, {goal:g}]
duration: {duration:g}
perception_radius: {perception:g}
robot_radius: {robot_radius:g}
plant: {{model: rover, mass: 40.0, stiffness: 20.0, damping: 45.0, spring_anchor: leg_target}}
controller:
  variant: nominal
  horizon: 10.0
  dt: 0.05
  M: 10.0
  R: 2.0
  P_T: 0.5
  alpha_c: 90.0
  alpha_a: 1.2
  rho: 0.15
  probing_std: 2.0
planner: {{steer_distance: 5.0}}
obstacles:
"""


def place_trees(rng: np.random.Generator, count: int, size: float, radii: tuple[float, float],
                gap: float, keep_clear: list[np.ndarray], clear: float,
                attempts: int = 200_000) -> np.ndarray:
    """Up to ``count`` trees as rows (x, y, r), m, none closer than ``gap`` to another.

    Fewer than ``count`` come back only when the square is full at this gap.
    """
    trees: list[tuple[float, float, float]] = []
    for _ in range(attempts):
        if len(trees) == count:
            break
        r = float(rng.uniform(*radii))
        c = rng.uniform(r, size - r, 2)
        if any(np.linalg.norm(c - p) < clear + r for p in keep_clear):
            continue
        if trees:
            arr = np.asarray(trees)
            if np.any(np.hypot(arr[:, 0] - c[0], arr[:, 1] - c[1]) < arr[:, 2] + r + gap):
                continue
        trees.append((float(c[0]), float(c[1]), r))
    return np.asarray(trees).reshape(-1, 3)


def forest_yaml(seed: int, count: int = 300, size: float = 100.0, gap: float = 2.5,
                radii: tuple[float, float] = (0.3, 1.0), late: float = 0.1,
                late_window: tuple[float, float] = (20.0, 150.0), perception: float = 8.0,
                robot_radius: float = 0.5, duration: float = 600.0, corner: float = 3.0,
                clear: float = 4.0, name: str | None = None) -> str:
    """The scenario text of one random forest (deterministic in ``seed``)."""
    rng = np.random.default_rng(seed)
    start, goal = corner, size - corner
    trees = place_trees(rng, count, size, radii, gap,
                        [np.array([start, start]), np.array([goal, goal])], clear)
    appear = np.where(rng.random(len(trees)) < late,
                      np.round(rng.uniform(*late_window, len(trees)), 1), 0.0)
    text = HEADER.format(size=size, count=len(trees), r_lo=radii[0], r_hi=radii[1], gap=gap,
                         perception=perception, late=int(np.count_nonzero(appear)),
                         seed=seed, name=name or f'forest-{size:g}-seed{seed}', start=start,
                         goal=goal, duration=duration, robot_radius=robot_radius)
    for i, ((x, y, r), t) in enumerate(zip(trees, appear)):
        timing = f', appear_at: {t:g}' if t > 0 else ''
        text += (f'  - {{id: tree{i:03d}, circle: {{center: [{x:.2f}, {y:.2f}], '
                 f'radius: {r:.2f}}}{timing}}}\n')
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--count', type=int, default=300, help='trees (default 300)')
    parser.add_argument('--size', type=float, default=100.0, help='side of the square, m')
    parser.add_argument('--gap', type=float, default=2.5, help='free space between trunks, m')
    parser.add_argument('--late', type=float, default=0.1,
                        help='fraction of trees that appear during the run')
    parser.add_argument('--name', default=None, help='scenario name (default from the seed)')
    parser.add_argument('--out', default='-', help='output file (default: stdout)')
    args = parser.parse_args(argv)
    text = forest_yaml(args.seed, count=args.count, size=args.size, gap=args.gap,
                       late=args.late, name=args.name)
    if args.out == '-':
        sys.stdout.write(text)
    else:
        with open(args.out, 'w', encoding='utf-8') as fh:
            fh.write(text)
    return 0
