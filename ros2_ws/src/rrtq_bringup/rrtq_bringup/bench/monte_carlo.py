"""``rrtq bench``: Monte Carlo over seeds, random obstacle layouts and configurations.

For each seed the base scenario gets a random obstacle layout
(:mod:`rrtq_bringup.bench.layouts`), written to ``RUNS/seed-NNN/scenario.yaml``, and
runs there as ``rrtq run --mode composed --speed max`` (lock-step: the seed fixes the
run).  ``--set KEY=V1,V2`` (repeatable, :mod:`rrtq_bringup.bench.sweep`) makes a
sweep: every configuration of the cross product runs every seed, in
``RUNS/cfg-NN/seed-NNN/``.  The engine runs them: ``local`` (default) ``--workers``
at a time on this machine (:mod:`rrtq_bringup.bench.local_engine`), ``ray`` as Ray tasks
on a cluster (:mod:`rrtq_bringup.bench.ray_engine`).  A progress bar on stderr counts
runs, successes and the time left; Ctrl-C or SIGTERM interrupts the runs in flight
(each ends its recording and summary) and writes the table of what completed.

The table (:mod:`rrtq_bringup.bench.table`) goes to ``OUT/monte_carlo.md`` and
``OUT/monte_carlo.json``; a sweep writes ``OUT/sweep.md``, ``.json`` and ``.png``
(:mod:`rrtq_bringup.bench.sweep_table`), a row per configuration.  The completed runs' own
leg scores are pooled into one calibration file beside the table, ``OUT/calibration.json``
(a sweep: ``OUT/calibration-cfg-NN.json`` per configuration), which a later scenario
starts from (``safety.calibration``; docs/margins.md §10).  Exit code 0 when
every run completed, whatever its mission outcome; 1 when a run crashed, timed out
or failed on the engine; 2 on bad input (nothing started); 130 when interrupted.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import shlex
import shutil
import sys
import time
from collections.abc import Callable
from typing import Any

import yaml

from rrtq_bringup.bench.control import evaluate
from rrtq_bringup.bench.layouts import (Layout, LayoutConfig, LayoutError, generate_layout,
                                        layout_scenario)
from rrtq_bringup.bench.local_engine import Job, Progress, Scheduler
# Imports no ray: the Ray engine imports it when it starts.
from rrtq_bringup.bench.ray_engine import RayEngine, RayUnavailable, cluster_text
from rrtq_bringup.bench.sweep import SweepError, apply, configurations, label, parse_setting
from rrtq_bringup.bench.sweep_table import sweep_markdown, sweep_plot
from rrtq_bringup.bench.table import COMPLETED, aggregate, machine, markdown
from rrtq_bringup.orchestrator import BadInput, check_supported
from rrtq_bringup.run_calibration import recorded_calibration
from rrtq_bringup.scenario import Scenario, ScenarioError, load_scenario, parse_scenario
from rrtq_controller.config import Variant
from rrtq_planner.margins.calibration import pooled, write_calibration

EXIT_OK, EXIT_INCOMPLETE, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
ROOT = pathlib.Path(os.environ.get('RRTQ_ROOT', pathlib.Path(__file__).resolve().parents[5]))


def _count(low: int) -> Callable[[str], int]:
    """An argparse type: an integer >= ``low``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None
        if value < low:
            raise argparse.ArgumentTypeError(f'must be >= {low}, got {value}')
        return value
    return parse


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='rrtq bench', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario', nargs='?', type=pathlib.Path,
                        default=ROOT / 'scenarios' / 'rrtqx_paper.yaml',
                        help='base scenario: bounds, start, goal, robot, plant, controller, '
                        'planner (its obstacles are replaced; default: the paper scenario)')
    parser.add_argument('--seeds', type=_count(1), default=50, help='number of seeds (50)')
    parser.add_argument('--first-seed', type=_count(0), default=0, help='first seed (0)')
    parser.add_argument('--workers', type=_count(1), default=os.cpu_count() or 1,
                        help='runs at a time (default: the number of cores)')
    parser.add_argument('--obstacles', type=_count(0), default=LayoutConfig.obstacles,
                        help=f'obstacles per layout ({LayoutConfig.obstacles})')
    parser.add_argument('--keep-obstacles', action='store_true',
                        help="keep the base scenario's obstacles and add the layout's to them "
                        '(a demo such as narrow_gap.yaml; the optimum path / layout check '
                        'then ignore the kept ones)')
    parser.add_argument('--out', type=pathlib.Path,
                        help='directory of monte_carlo.md and .json (default: the runs '
                        'directory)')
    parser.add_argument('--runs', type=pathlib.Path,
                        help='directory of the runs, one seed-NNN/ each '
                        '(default: runs/bench/<scenario name>)')
    parser.add_argument('--run-timeout', type=_count(1), default=1800,
                        help='wall seconds after which a run is stopped as timed out (1800)')
    parser.add_argument('--overwrite', action='store_true',
                        help='replace the seed directories of an earlier bench')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=V1,V2',
                        dest='settings',
                        help='sweep a scenario key (dotted path, e.g. controller.R=0.02,2; '
                        'values read as YAML); repeat for more keys: the cross product runs, '
                        'every configuration over the same seeds')
    parser.add_argument('--engine', choices=('local', 'ray'), default='local',
                        help='local: --workers runs at a time on this machine (default); '
                        'ray: one Ray task per run on a cluster')
    parser.add_argument('--address', metavar='ADDR',
                        help='--engine ray: the cluster to join (HOST:PORT of its head, or '
                        "'auto' for the one running on this machine); default: a private Ray "
                        'instance on this machine with --workers CPUs')
    return parser


@dataclasses.dataclass(frozen=True)
class Configuration:
    """One configuration of a sweep (the only one without ``--set``)."""

    index: int
    overrides: dict[str, Any]
    document: dict[str, Any]      # the base scenario's mapping with the overrides set
    scenario: Scenario
    runs: pathlib.Path            # its seed-NNN/ directories go here

    @property
    def label(self) -> str:
        return label(self.overrides)


def _configurations(args: argparse.Namespace, base: Scenario, document: dict[str, Any],
                    runs: pathlib.Path) -> list[Configuration]:
    """Every configuration, validated as the scenario loader validates a file."""
    settings = [parse_setting(text) for text in args.settings]
    out = []
    for index, overrides in enumerate(configurations(settings)):
        doc = apply(document, overrides)
        try:
            scenario = parse_scenario(doc, str(args.scenario)) if overrides else base
        except ScenarioError as exc:
            raise BadInput(f'{exc} (with --set {label(overrides)})') from None
        check_supported(scenario)
        if str(scenario.controller.variant) == 'open_loop':
            raise BadInput(f'{scenario.path}: controller.variant: open_loop has no goal to '
                           'reach; the bench needs the planner and a learning controller')
        out.append(Configuration(index, overrides, doc, scenario,
                                 runs / f'cfg-{index:02d}' if settings else runs))
    return out


def _prepare(conf: Configuration, seeds: range, config: LayoutConfig,
             layouts: dict[tuple, Layout], keep: bool = False) -> list[Job]:
    """Draw every seed's layout, then write its scenario file and check it as a run would.

    ``layouts`` caches them across configurations: a layout depends on the seed and
    the geometry (bounds, start, goal, robot and perception radii) only.
    """
    base = conf.scenario
    geometry = (str(base.bounds), tuple(base.start), tuple(base.goal), base.robot_radius,
                base.perception_radius)
    jobs = []
    for seed in seeds:
        if (seed, geometry) not in layouts:
            layouts[seed, geometry] = generate_layout(base, seed, config)
        layout = layouts[seed, geometry]
        out = conf.runs / f'seed-{layout.seed:03d}'
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir(parents=True)
        path = out / 'scenario.yaml'
        name = (f'{base.name}-cfg-{conf.index:02d}-seed-{layout.seed:03d}' if conf.overrides
                else f'{base.name}-seed-{layout.seed:03d}')
        doc = layout_scenario(conf.document, layout, name, keep)
        if base.controller.model:      # relative to the base file, which stays where it is
            doc['controller']['model'] = base.controller.model
        path.write_text(f'# rrtq bench: {base.path} with the random layout of seed '
                        f'{layout.seed}'
                        + (f'; --set {conf.label}' if conf.overrides else '') + '\n'
                        + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
        (out / 'layout.json').write_text(json.dumps({
            'seed': layout.seed, 'attempts': layout.attempts,
            'optimum_m': layout.optimum.length, 'optimum_path': layout.optimum.path.tolist(),
            'route_m': layout.route.length, 'config': dataclasses.asdict(config)},
            indent=1) + '\n')
        load_scenario(path)
        to_disc = max(0.0, layout.optimum.length - base.goal_tolerance)
        jobs.append(Job(layout.seed, out, path, to_disc, conf.index))
    return jobs


def _run_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per-run lines of the JSON table."""
    keys = ('success', 'collided', 'outcome', 'reason', 'time_to_goal_s', 'path_length_m',
            'min_clearance_m', 'replans', 'replan_ms', 'controller_step_ms', 'sim_speedup',
            'sim_time_s', 'wall_time_s')
    out = []
    for row in rows:
        s = row['summary']
        ratio = (s['path_length_m'] / row['optimum_m']
                 if row['status'] == COMPLETED and s.get('success') else None)
        engine = {k: row[k] for k in ('attempts', 'retried_after', 'node') if k in row}
        out.append({'seed': row['seed'], 'status': row['status'], 'dir': row['dir'],
                    'optimum_m': row['optimum_m'], 'path_over_optimum': ratio,
                    **{k: s.get(k) for k in keys}, 'control': row.get('control'), **engine})
    return out


def _pool_calibration(rows: list[dict[str, Any]], path: pathlib.Path, what: str) -> str | None:
    """Pool the completed runs' own leg scores into the calibration file ``path``."""
    runs = [r for r in rows if r['status'] == COMPLETED
            and (pathlib.Path(r['dir']) / 'run.mcap').exists()]
    if not runs:
        return None
    created = time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())
    seeds = sorted(r['seed'] for r in runs)
    calibration = pooled((recorded_calibration(pathlib.Path(r['dir']) / 'run.mcap')
                          for r in runs),
                         f'rrtq bench: {what}, seeds {", ".join(map(str, seeds))}', created)
    write_calibration(path, calibration)
    return str(path)


def _layout_text(config: LayoutConfig, base: Scenario) -> str:
    known = int(config.obstacles * config.known_fraction)
    return (f'Base scenario `{base.path}` ({base.name}); per seed {config.obstacles} random '
            f'obstacles (rectangles and circles, {config.size[0]:g}–{config.size[1]:g} m): '
            f'{known} known from t = 0 about the start–goal line, {config.obstacles - known} '
            'appearing about the route, timed to appear within perception range; an '
            'obstacle never appears within '
            f'{base.appear_clearance:g} m of the robot (`appear_clearance`). Composed mode, '
            'lock-step. Optimum: shortest path with every obstacle present, grown by the '
            f'robot radius ({base.robot_radius:g} m), on the visibility graph, to within '
            f"the goal tolerance ({base.goal_tolerance:g} m) where a run stops.")


def _engine(args: argparse.Namespace, jobs: list[Job]):
    """The scheduler of ``--engine``, and how the table names it."""
    progress = Progress(len(jobs))
    if args.engine == 'local':
        return (Scheduler(jobs, args.workers, float(args.run_timeout), progress),
                f'local, {args.workers} workers')
    engine = RayEngine(jobs, args.address, args.workers, float(args.run_timeout), progress)
    return engine, cluster_text(engine)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = _parser().parse_args(argv)
    config = LayoutConfig(obstacles=args.obstacles)
    try:
        if args.address is not None and args.engine != 'ray':
            raise BadInput('--address needs --engine ray')
        base = load_scenario(args.scenario)
        document = yaml.safe_load(args.scenario.read_text())
        runs = args.runs or pathlib.Path('runs') / 'bench' / base.name
        confs = _configurations(args, base, document, runs)
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        earlier = [c.runs / f'seed-{s:03d}' for c in confs for s in seeds
                   if (c.runs / f'seed-{s:03d}').exists()]
        if earlier and not args.overwrite:
            raise BadInput(f'{earlier[0]} exists (an earlier bench); choose another --runs or '
                           'pass --overwrite')
        layouts: dict[tuple, Layout] = {}
        jobs = [job for conf in confs for job in _prepare(conf, seeds, config, layouts, args.keep_obstacles)]
        scheduler, engine_text = _engine(args, jobs)
    except (ScenarioError, BadInput, LayoutError, SweepError, RayUnavailable) as exc:
        print(f'rrtq bench: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    out = args.out or runs
    sweep = bool(args.settings)
    print(f'rrtq bench: {len(seeds)} seeds of {base.name} ({args.obstacles} obstacles each)'
          + (f' x {len(confs)} configurations' if sweep else '')
          + f', engine {engine_text} -> {runs}', file=sys.stderr)
    if base.obstacles and not args.keep_obstacles:
        print(f'rrtq bench: the base scenario\'s obstacles ({len(base.obstacles)}) are replaced '
              'by each seed\'s layout (--keep-obstacles keeps them)', file=sys.stderr)
    started = time.monotonic()
    rows = sorted(scheduler.run(), key=lambda r: (r['config'], r['seed']))
    if any(c.scenario.controller.variant in (Variant.NOMINAL, Variant.ROBUST) for c in confs):
        done = sum(1 for r in rows if r['status'] == COMPLETED)
        print(f'rrtq bench: reading the legs of {done} recordings (last-ten leg cost against '
              'the Riccati policy, largest command)', file=sys.stderr)
        evaluate(rows, args.workers)
    table = {
        'machine': machine(pathlib.Path(__file__).resolve().parent),
        'command': 'rrtq bench ' + shlex.join(argv),
        'scenario': str(args.scenario), 'seeds': f'{seeds.start}–{seeds.stop - 1}',
        'engine': engine_text, 'workers': args.workers, 'wall_s': time.monotonic() - started,
        'layout': _layout_text(config, base), 'layout_config': dataclasses.asdict(config),
        'interrupted': scheduler.stop,
    }
    out.mkdir(parents=True, exist_ok=True)
    for c in confs:
        name = f'calibration-cfg-{c.index:02d}.json' if sweep else 'calibration.json'
        what = f'{base.name} --set {c.label}' if sweep else base.name
        path = _pool_calibration([r for r in rows if r['config'] == c.index], out / name, what)
        if path is not None:
            print(f'rrtq bench: leg scores pooled in {path} (a later run\'s '
                  'safety.calibration)', file=sys.stderr)
    if sweep:
        table['settings'] = args.settings
        table['configurations'] = [
            {'index': c.index, 'overrides': c.overrides, 'label': c.label, 'dir': str(c.runs),
             'stats': aggregate([r for r in rows if r['config'] == c.index]),
             'runs': _run_rows([r for r in rows if r['config'] == c.index])} for c in confs]
        (out / 'sweep.json').write_text(json.dumps(table, indent=2) + '\n')
        (out / 'sweep.md').write_text(sweep_markdown(table))
        sweep_plot(table, out / 'sweep.png')
        for c in table['configurations']:
            s = c['stats']
            print(json.dumps({'configuration': c['label'], 'runs': s['runs'],
                              'completed': s['completed'], 'success_rate': s['success_rate'],
                              'collision_rate': s['collision_rate']}))
        print(f'rrtq bench: table in {out / "sweep.md"}, plot in {out / "sweep.png"}',
              file=sys.stderr)
    else:
        table.update({'stats': aggregate(rows), 'runs': _run_rows(rows)})
        (out / 'monte_carlo.json').write_text(json.dumps(table, indent=2) + '\n')
        (out / 'monte_carlo.md').write_text(markdown(table))
        stats = table['stats']
        print(json.dumps({k: stats[k] for k in ('runs', 'completed', 'success_rate',
                                                 'collision_rate')}))
        print(f'rrtq bench: table in {out / "monte_carlo.md"}', file=sys.stderr)
    if scheduler.stop:
        return EXIT_INTERRUPTED
    done = sum(1 for r in rows if r['status'] == COMPLETED)
    return EXIT_OK if done == len(rows) else EXIT_INCOMPLETE


if __name__ == '__main__':
    sys.exit(main())
