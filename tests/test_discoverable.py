"""Discoverable environments: Otte flags, obstacles that appear and vanish, judged from a run.

One closed-loop run (composed, lock-step) in a small Otte-style world: a block the robot
believes in but that is not there (flag -1) across the straight way, a block that is
there but unknown (flag 1) and known walls (flag 0). From the recording alone: the
believed block leaves /obstacles/detected when the robot sees its place and the robot
then drives through that place, the unknown one joins the map when the robot sees it,
and the robot reaches the goal without touching what really exists (judged from /odom
against the file's geometry, not against any node's opinion).
The rest is fast: path resolution, the shipped scenarios, the forest generator.
"""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess

import numpy as np
import pytest
import yaml

from rrtq_bringup import forest as make_forest
from rrtq_bringup.leg_costs import evaluate
from rrtq_bringup.report.run import report
from rrtq_bringup.run_data import read_run
from rrtq_bringup.scenario import load_scenario
from rrtq_common.geometry import point_in_polygon, point_polygon_distance
from rrtq_common.otte import load_otte
from rrtq_testing.paths import OTTE

ROOT = pathlib.Path(__file__).resolve().parents[1]

# Flags: 0 known, 1 unknown until sensed, -1 believed present but absent.
WORLD = """4
4
-1.5, -2
0.5, -2
0.5, 2
-1.5, 2
-1
4
3.5, -1
4.1, -1
4.1, 1
3.5, 1
1
4
-5, 2.5
-4.5, 2.5
-4.5, 5
-5, 5
0
4
-5, -5
-4.5, -5
-4.5, -2.5
-5, -2.5
0
"""
GHOST, HIDDEN = 'world_0', 'world_1'
PERCEPTION = 5.0
ROBOT_RADIUS = 0.3

SCENARIO = f"""
name: discoverable
seed: 2
bounds: {{x: [-9, 9], y: [-5, 5]}}
start: [-7.0, 0.0]
goal: [7.0, 0.0]
duration: 60.0
perception_radius: {PERCEPTION}
robot_radius: {ROBOT_RADIUS}
plant: {{model: rover, mass: 40.0, stiffness: 20.0, damping: 45.0, spring_anchor: leg_target}}
controller: {{variant: nominal, M: 10.0, R: 2.0, P_T: 0.5, alpha_c: 90.0, alpha_a: 1.2,
             probing_std: 2.0}}
planner: {{steer_distance: 3.0, iterations_per_step: 20, max_nodes: 800}}
obstacles:
  - {{file: ../envs/world.txt, format: otte, discoverable: true}}
"""


def write_world(tmp: pathlib.Path) -> pathlib.Path:
    """The scenario in tmp/scenarios/, its Otte file in tmp/envs/ (a ../ path)."""
    (tmp / 'envs').mkdir()
    (tmp / 'envs' / 'world.txt').write_text(WORLD)
    (tmp / 'scenarios').mkdir()
    path = tmp / 'scenarios' / 'discoverable.yaml'
    path.write_text(SCENARIO)
    return path


def test_otte_paths_resolve_against_the_scenario_file_not_the_cwd(tmp_path, monkeypatch):
    path = write_world(tmp_path)
    monkeypatch.chdir(tmp_path / 'envs')          # ../envs/world.txt would miss from here
    scenario = load_scenario(os.path.relpath(path))
    by_id = {spec.id: spec for spec in scenario.obstacles}
    assert list(by_id) == ['world_0', 'world_1', 'world_2', 'world_3']
    ghost, hidden = by_id[GHOST], by_id[HIDDEN]
    assert ghost.known and not ghost.ever_exists                    # -1
    assert not hidden.known and hidden.exists(0.0)                  # 1
    assert by_id['world_2'].known and by_id['world_2'].exists(1e6)  # 0


def test_discovered_and_vanished_obstacles_reach_the_map_and_the_goal_is_reached(tmp_path):
    path = write_world(tmp_path)
    out = tmp_path / 'run'
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(path), '--out', str(out),
                           '--mode', 'composed'], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    data = read_run(out / 'run.mcap')

    # The map: starts with what is known (the ghost included, the hidden block not).
    maps = [(t, {oid for oid, _ in obstacles}) for t, obstacles in data.detected]
    assert maps[0][0] == 0.0 and maps[0][1] == {GHOST, 'world_2', 'world_3'}
    removed = next(t for t, ids in maps if GHOST not in ids)
    added = next(t for t, ids in maps if HIDDEN in ids)
    assert all(GHOST not in ids for t, ids in maps if t >= removed)   # once gone, gone
    polygons = {f'world_{i}': poly for i, (poly, _) in enumerate(load_otte(
        tmp_path / 'envs' / 'world.txt'))}
    for oid, t in ((GHOST, removed), (HIDDEN, added)):
        # Sensed the first step its place came within the perception disc, not before.
        gaps = point_polygon_distance(data.odom_x[:, :2], polygons[oid])
        first = data.odom_t[np.flatnonzero(gaps <= PERCEPTION)[0]]
        assert t == pytest.approx(first), oid
    # Once the ghost is gone the planner fills its place, and the robot drives through.
    crossing = data.odom_t[point_in_polygon(data.odom_x[:, :2], polygons[GHOST])]
    assert crossing.size and crossing.min() > removed
    # The truth never holds the ghost, and holds the hidden block from the start.
    assert all(GHOST not in {oid for oid, _ in obstacles} for _, obstacles in data.truth)
    assert HIDDEN in {oid for oid, _ in data.truth[0][1]}

    # Goal reached, judged from /odom alone; no contact with what really exists.
    goal = np.array([7.0, 0.0])
    assert np.linalg.norm(data.odom_x[-1, :2] - goal) <= 0.5
    real = [poly for oid, poly in polygons.items() if oid != GHOST]
    gap = min(point_polygon_distance(data.odom_x[:, :2], poly).min() for poly in real)
    assert gap > ROBOT_RADIUS

    # The report reads a recording whose scenario names an obstacle file not beside it.
    summary = report(out / 'run.mcap')
    assert summary['collided'] is False
    assert summary['min_clearance_m'] == pytest.approx(gap - ROBOT_RADIUS, abs=1e-6)
    assert (out / 'report' / 'map.png').stat().st_size > 0
    assert json.loads((out / 'summary.json').read_text())['outcome'] == 'goal_reached'
    # So do the leg costs (plant and weights from the embedded scenario, no obstacle file),
    # also where ../envs/world.txt does not resolve from the recording.
    moved = tmp_path / 'moved' / 'deeper'
    moved.mkdir(parents=True)
    shutil.copy(out / 'run.mcap', moved / 'run.mcap')
    legs = evaluate(moved / 'run.mcap')
    assert legs.rows and np.all(np.isfinite(legs.column('ratio')))


# ---------------------------------------------------------------- the shipped scenarios


def test_forest_generator_keeps_its_gaps_and_the_shipped_forest_is_its_output():
    text = make_forest.forest_yaml(5, count=150, size=60.0)
    data = yaml.safe_load(text)
    trees = [(np.array(o['circle']['center']), o['circle']['radius']) for o in data['obstacles']]
    assert len(trees) == 150
    centers = np.array([c for c, _ in trees])
    radii = np.array([r for _, r in trees])
    apart = np.linalg.norm(centers[:, None] - centers[None], axis=2) - radii[:, None] - radii
    np.fill_diagonal(apart, np.inf)
    assert apart.min() >= 2.5
    for corner in (data['start'], data['goal']):
        assert (np.linalg.norm(centers - corner, axis=1) - radii).min() >= 4.0
    late = [o for o in data['obstacles'] if 'appear_at' in o]
    assert 0 < len(late) < len(trees)
    assert make_forest.forest_yaml(5, count=150, size=60.0) == text        # seeded
    assert make_forest.forest_yaml(6, count=150, size=60.0) != text
    shipped = (ROOT / 'scenarios' / 'forest_100.yaml').read_text()
    seed = yaml.safe_load(shipped)['seed']
    assert make_forest.forest_yaml(seed, name='forest-100') == shipped


@pytest.mark.parametrize('name', ['otte_discoverable.yaml', 'forest_100.yaml'])
def test_shipped_discoverable_scenarios_load(name):
    scenario = load_scenario(ROOT / 'scenarios' / name)
    kinds = {(spec.known, spec.ever_exists, spec.appear_at > 0, spec.vanish_at < np.inf)
             for spec in scenario.obstacles}
    assert (False, True, False, False) in kinds          # there, unknown until sensed
    if name == 'otte_discoverable.yaml':
        assert (True, False, False, True) in kinds       # believed, absent (Otte -1)
        assert (True, True, False, True) in kinds        # known, goes away during the run
    assert (False, True, True, False) in kinds           # appears during the run


def test_the_otte_copy_keeps_the_original_geometry():
    # the original as vendored, byte for byte, with its provenance and licence beside it
    original = OTTE / 'rand_Static.txt'
    ours = load_otte(ROOT / 'scenarios' / 'envs' / 'rand_discoverable.txt')
    theirs = load_otte(original)
    assert len(ours) == len(theirs) == 35
    assert {flag for _, flag in theirs} == {0}
    for (a, _), (b, _) in zip(ours, theirs):
        np.testing.assert_array_equal(a, b)
    assert {flag for _, flag in ours} == {-1, 0, 1}

