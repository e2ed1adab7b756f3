"""``rrtq``: run scenarios, plan, report and benchmark (Monte Carlo).

Exit codes: 0 success, 1 failed mission (also a run stopped by Ctrl-C or SIGTERM), 2 bad
input (nothing started). ``rrtq plant`` exits 0 at its duration or on Ctrl-C/SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys

EXIT_BAD_INPUT = 2
LIVE_PORT = 8765      # Foxglove's default WebSocket port


def _speed(text: str) -> float:
    if text == 'max':
        return 0.0
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'max' or a positive factor, got {text!r}") from None
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f'speed factor must be > 0, got {text}')
    return value


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f'must be > 0, got {text}')
    return value


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a TCP port number, got {text!r}') from None
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f'port must be in 1..65535, got {value}')
    return value


def _port_free(port: int) -> bool:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        try:
            probe.bind(('127.0.0.1', port))
        except OSError:
            return False
    return True


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='rrtq', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest='command', required=True)
    run = sub.add_parser('run', help='run a scenario end to end, recorded to MCAP')
    run.add_argument('scenario', type=pathlib.Path, help='scenario YAML file')
    run.add_argument('--out', type=pathlib.Path,
                     help='output directory (default: runs/<scenario name>)')
    run.add_argument('--seed', type=int, help="override the scenario's seed")
    run.add_argument('--speed', type=_speed, default=0.0,
                     help="'max' (lock-step, default) or a wall-clock pace factor, e.g. 1.0")
    run.add_argument('--mode', choices=('processes', 'composed'), default='processes',
                     help='one process per node (default) or all nodes on one executor')
    run.add_argument('--overwrite', action='store_true',
                     help='replace an existing recording in the output directory')
    run.add_argument('--live', type=_port, nargs='?', const=LIVE_PORT, metavar='PORT',
                     help='also serve the running graph to Foxglove over its WebSocket '
                     f'protocol on ws://127.0.0.1:PORT (default port {LIVE_PORT}); in '
                     'lock-step the view follows the run as fast as it goes')
    robot = sub.add_parser('robot', help="the robot's side alone (planner, controller, "
                           'safety, recorder) against an external /odom and perception')
    robot.add_argument('scenario', type=pathlib.Path, help='scenario YAML file')
    robot.add_argument('--out', type=pathlib.Path,
                       help='output directory (default: runs/<scenario name>-robot)')
    robot.add_argument('--overwrite', action='store_true',
                       help='replace an existing recording in the output directory')
    robot.add_argument('--live', type=_port, nargs='?', const=LIVE_PORT, metavar='PORT',
                       help='also serve the graph to Foxglove on ws://127.0.0.1:PORT '
                       f'(default port {LIVE_PORT})')
    robot.add_argument('--clock', choices=('auto', 'sim', 'wall'), default='auto',
                       help="the nodes' time: 'auto' (default) waits for a publisher of /odom or "
                       "/clock and takes sim time when /clock has one (within 2 s of /odom's), "
                       'else wall time')
    robot.add_argument('--odometry-timeout', type=_positive, metavar='S',
                       help='run time without odometry after which the run fails as '
                       "'odometry lost' (default 10 x the controller's 3 dt; never "
                       'before 1 s of wall time)')
    plant = sub.add_parser('plant', help="the scenario's plant, disturbance injector and "
                           'obstacle spawner as one process for rrtq robot')
    plant.add_argument('scenario', type=pathlib.Path, help='scenario YAML file')
    plant.add_argument('--speed', type=_positive, default=1.0,
                       help='pace factor against real time (default 1)')
    plant.add_argument('--command-timeout', type=_positive, metavar='S',
                       help='sim time after the last /cmd_force after which zero force is '
                       'held (default 0.5)')
    sub.add_parser('plan', help='the RRT^X planner alone on a scenario or Otte file; '
                   "'rrtq plan --help' for its options", add_help=False)
    sub.add_parser('bench', help='Monte Carlo over seeds and random obstacle layouts; '
                   "'rrtq bench --help' for its options", add_help=False)
    sub.add_parser('identify', help='fit the Koopman model of the plant from a recording; '
                   "'rrtq identify --help' for its options", add_help=False)
    rep = sub.add_parser('report', help='figures and summary from a recording alone')
    rep.add_argument('recording', type=pathlib.Path, help='run.mcap of a run')
    rep.add_argument('--out', type=pathlib.Path,
                     help='output directory (default: report/ beside the recording)')
    rep.add_argument('--video', action='store_true',
                     help='also write run.mp4 (ffmpeg) or run.gif (Pillow) of the run')
    rep.add_argument('--frame-interval', type=_positive, default=0.5, metavar='S',
                     help='simulated seconds per video frame (default 0.5)')
    rep.add_argument('--fps', type=_positive, default=10.0,
                     help='video frames per second of playback (default 10)')
    return parser


def _report(out: pathlib.Path, keys: tuple[str, ...]) -> None:
    """Print the run's summary (``keys`` of OUT/summary.json) and a failed node's log tail."""
    summary = json.loads((out / 'summary.json').read_text())
    print(json.dumps({k: summary[k] for k in keys}))
    if summary.get('failed_node'):
        failed = summary['failed_node']
        print(f"rrtq: node '{failed['node']}' {failed['status']}; last lines of its log:",
              file=sys.stderr)
        print('\n'.join('  ' + line for line in failed['log_tail']), file=sys.stderr)


def cmd_run(args: argparse.Namespace) -> int:
    from rrtq_bringup.orchestrator import BadInput, Run, RunMode, RunOptions, check_supported
    from rrtq_bringup.scenario import ScenarioError, load_scenario

    try:
        scenario = load_scenario(args.scenario, seed=args.seed)
        check_supported(scenario)
        out = args.out or pathlib.Path('runs') / scenario.name
        if (out / 'run.mcap').exists() and not args.overwrite:
            raise BadInput(f'{out / "run.mcap"} exists; choose another --out or pass '
                           '--overwrite')
        if args.live is not None and not _port_free(args.live):
            raise BadInput(f'--live: port {args.live} on 127.0.0.1 is in use')
    except (ScenarioError, BadInput) as exc:
        print(f'rrtq: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    for stale in ('run.mcap', 'summary.json'):
        (out / stale).unlink(missing_ok=True)
    options = RunOptions(out_dir=out, speed=args.speed, mode=RunMode(args.mode),
                         live_port=args.live)
    print(f'rrtq: running {scenario.name} (seed {scenario.seed}, {args.mode}, speed '
          f"{'max' if args.speed == 0 else args.speed}) -> {out}", file=sys.stderr)
    if args.live is not None:
        print(f'rrtq: live view on ws://127.0.0.1:{args.live} (Foxglove: Open connection, '
              'Foxglove WebSocket)', file=sys.stderr)
    code = Run(scenario, options).execute()
    _report(out, ('success', 'outcome', 'reason', 'sim_time_s', 'sim_speedup', 'recording'))
    return code


def cmd_robot(args: argparse.Namespace) -> int:
    from rrtq_bringup.orchestrator import BadInput, check_supported
    from rrtq_bringup.robot import ClockSource, RobotOptions, RobotRun
    from rrtq_bringup.scenario import ScenarioError, load_scenario

    try:
        scenario = load_scenario(args.scenario)
        check_supported(scenario)
        out = args.out or pathlib.Path('runs') / f'{scenario.name}-robot'
        if (out / 'run.mcap').exists() and not args.overwrite:
            raise BadInput(f'{out / "run.mcap"} exists; choose another --out or pass '
                           '--overwrite')
        if args.live is not None and not _port_free(args.live):
            raise BadInput(f'--live: port {args.live} on 127.0.0.1 is in use')
    except (ScenarioError, BadInput) as exc:
        print(f'rrtq: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    for stale in ('run.mcap', 'summary.json'):
        (out / stale).unlink(missing_ok=True)
    options = RobotOptions(out_dir=out, live_port=args.live, clock=ClockSource(args.clock),
                           odometry_timeout_s=args.odometry_timeout)
    domain = os.environ.get('ROS_DOMAIN_ID', '0') or '0'
    print(f'rrtq: robot side of {scenario.name} on ROS_DOMAIN_ID={domain} -> {out}',
          file=sys.stderr)
    code = RobotRun(scenario, options).execute()
    _report(out, ('success', 'outcome', 'reason', 'sim_time_s', 'clock', 'recording'))
    return code


def cmd_plant(args: argparse.Namespace) -> int:
    from rrtq_bringup.orchestrator import BadInput, check_supported
    from rrtq_bringup.plant_process import PlantProcessConfig, run_plant
    from rrtq_bringup.scenario import ScenarioError, load_scenario

    try:
        scenario = load_scenario(args.scenario)
        check_supported(scenario)
    except (ScenarioError, BadInput) as exc:
        print(f'rrtq: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    config = (PlantProcessConfig(command_timeout_s=args.command_timeout)
              if args.command_timeout else PlantProcessConfig())
    return run_plant(scenario, args.speed, config)


def cmd_report(args: argparse.Namespace) -> int:
    if not args.recording.is_file():
        print(f'rrtq: error: {args.recording}: no such recording', file=sys.stderr)
        return EXIT_BAD_INPUT
    from mcap.exceptions import McapError
    from rrtq_bringup.report.run import report
    try:
        summary = report(args.recording, args.out,
                         video_interval=args.frame_interval if args.video else None,
                         video_fps=args.fps)
    except (McapError, ValueError) as exc:
        print(f'rrtq: error: {args.recording}: not a readable recording ({exc})',
              file=sys.stderr)
        return EXIT_BAD_INPUT
    out = args.out or args.recording.parent / 'report'
    print(json.dumps({k: summary[k] for k in ('sim_time_s', 'path_length_m', 'min_clearance_m',
                                               'collided', 'time_to_goal_s')}))
    print(f'rrtq: figures in {out}', file=sys.stderr)
    if 'video' in summary:
        print(f"rrtq: video {summary['video']}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['plan']:
        from rrtq_bringup.plan_cli import main as plan_main
        return plan_main(argv[1:])
    if argv[:1] == ['bench']:
        from rrtq_bringup.bench.monte_carlo import main as bench_main
        return bench_main(argv[1:])
    if argv[:1] == ['identify']:
        from rrtq_bringup.identify import main as identify_main
        return identify_main(argv[1:])
    args = _parser().parse_args(argv)
    return {'run': cmd_run, 'robot': cmd_robot, 'plant': cmd_plant,
            'report': cmd_report}[args.command](args)


if __name__ == '__main__':
    sys.exit(main())
