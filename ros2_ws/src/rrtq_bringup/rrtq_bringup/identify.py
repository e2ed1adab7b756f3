"""``rrtq identify RUN.mcap -o model.npz``: fit the nominal Koopman model from a recording.

The triples (x_k, u_k, x_{k+1}) come from ``/odom`` (x = p_x, p_y, v_x, v_y) and
``/cmd_force`` (u = f_x, f_y): in lock-step the command stamped t_k is what the plant
held over [t_k, t_k + dt], and x_{k+1} is the odometry stamped t_k + dt. Commands are
clipped at the actuator limit of the embedded scenario (``controller.force_limit``, else
``plant.force_limit``), which is what the plant applied. The last ``--holdout`` share of
the samples (in time) is held back; the one-step and 2 s open-loop prediction errors on
it are printed as one JSON line.

Exit codes: 0 model written; 2 bad input (missing or unreadable file, no ``/odom`` or
``/cmd_force``, too few samples), the file named on stderr.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import pathlib
import sys
from collections.abc import Sequence

import numpy as np
import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rrtq_bringup.run_data import embedded_scenario
from rrtq_controller.vf_lpc.koopman import LIFTINGS, fit_edmd, prediction_errors
from rrtq_sim.plant import PlantConfig

EXIT_BAD_INPUT = 2
# Fewer triples than this per fitted parameter row cannot pin the model down.
MIN_SAMPLES = 50
OPEN_LOOP_S = 2.0
PLANT_FORCE_LIMIT = next(f.default for f in dataclasses.fields(PlantConfig) if f.name == 'force_limit')


class BadInput(Exception):
    """Unusable input; the message names the file."""


def _ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def read_triples(path: pathlib.Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, float,
                                             list[tuple[int, int]], float]:
    """(x, u, x_next, dt, segments, force_limit) from a recording.

    ``segments`` are the [start, end) row ranges of samples that follow each other
    without a gap.
    """
    if not path.is_file():
        raise BadInput(f'{path}: no such recording')
    odom: dict[int, list[float]] = {}
    cmd: dict[int, list[float]] = {}
    limit = math.inf
    factory = DecoderFactory()
    try:
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[factory])
            for _, channel, _, msg in reader.iter_decoded_messages(
                    topics=['/odom', '/cmd_force']):
                if channel.topic == '/odom':
                    p, v = msg.pose.pose.position, msg.twist.twist.linear
                    odom[_ns(msg.header)] = [p.x, p.y, v.x, v.y]
                else:
                    cmd[_ns(msg.header)] = [msg.wrench.force.x, msg.wrench.force.y]
        scenario = embedded_scenario(path)
        if scenario:        # what the plant applied: the scenario's limit, or its default
            plant_limit = (scenario.get('plant') or {}).get('force_limit', PLANT_FORCE_LIMIT)
            value = (scenario.get('controller') or {}).get('force_limit', plant_limit)
            limit = float(value)
    except (McapError, OSError, ValueError, KeyError, yaml.YAMLError) as exc:
        raise BadInput(f'{path}: not a readable recording ({exc})') from None
    for topic, data in (('/odom', odom), ('/cmd_force', cmd)):
        if not data:
            raise BadInput(f'{path}: no {topic} messages')
    stamps = np.array(sorted(odom))
    if len(stamps) < 2:
        raise BadInput(f'{path}: fewer than two /odom messages')
    dt_ns = int(np.median(np.diff(stamps)))
    rows = [t for t in sorted(cmd) if t in odom and t + dt_ns in odom]
    if len(rows) < MIN_SAMPLES:
        raise BadInput(f'{path}: only {len(rows)} (odom, cmd_force, next odom) samples; '
                       f'need at least {MIN_SAMPLES}')
    x = np.array([odom[t] for t in rows])
    u = np.clip(np.array([cmd[t] for t in rows]), -limit, limit)
    xn = np.array([odom[t + dt_ns] for t in rows])
    breaks = np.flatnonzero(np.diff(rows) != dt_ns) + 1
    edges = [0, *breaks.tolist(), len(rows)]
    segments = list(zip(edges[:-1], edges[1:]))
    return x, u, xn, dt_ns * 1e-9, segments, limit


def identify(path: pathlib.Path, out: pathlib.Path, holdout: float,
             observables: str) -> dict:
    """Fit on the first 1 - holdout of the samples, evaluate on the rest, write ``out``."""
    x, u, xn, dt, segments, limit = read_triples(path)
    cut = int(round(len(x) * (1.0 - holdout)))
    if cut < MIN_SAMPLES or (holdout > 0.0 and len(x) - cut < 2):
        raise BadInput(f'{path}: {len(x)} samples are too few for a hold-out of {holdout:g}')
    model = fit_edmd(x[:cut], u[:cut], xn[:cut], dt, observables, force_limit=limit)
    model.save(out)
    held = [(max(lo, cut), hi) for lo, hi in segments if hi > cut]
    steps = int(round(OPEN_LOOP_S / dt))
    report: dict = {'model': str(out), 'samples': len(x), 'fitted_on': cut,
                    'held_out': len(x) - cut, 'dt_s': dt, 'observables': observables,
                    'force_limit_N': limit}
    if held and len(x) > cut:
        rows = np.r_[tuple(np.arange(lo, hi) for lo, hi in held)]
        shifted, start = [], 0
        for lo, hi in held:
            shifted.append((start, start + hi - lo))
            start += hi - lo
        errors = prediction_errors(model, x[rows], u[rows], xn[rows], shifted, steps)
        report.update({f'holdout_{k}': v for k, v in errors.items()})
        report['open_loop_horizon_s'] = OPEN_LOOP_S
    return report


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='rrtq identify',
        description='Fit the Koopman / EDMD-with-control model of the plant from a '
                    'recording (/odom, /cmd_force); print its hold-out errors as JSON.')
    parser.add_argument('recording', type=pathlib.Path, metavar='RUN.mcap')
    parser.add_argument('-o', '--out', type=pathlib.Path, required=True, metavar='FILE',
                        help='model file to write (.npz)')
    parser.add_argument('--holdout', type=float, default=0.2, metavar='F',
                        help='share of the samples (the last, in time) held back for the '
                             'error report (default 0.2)')
    parser.add_argument('--observables', choices=sorted(LIFTINGS), default='linear',
                        help='lifting psi(x) (default linear: psi(x) = x)')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(None if argv is None else list(argv))
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    try:
        if not 0.0 <= args.holdout < 1.0:
            raise BadInput(f'--holdout must be in [0, 1), got {args.holdout}')
        report = identify(args.recording, args.out, args.holdout, args.observables)
    except BadInput as exc:
        print(f'rrtq identify: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    print(json.dumps(report))
    return 0


if __name__ == '__main__':
    sys.exit(main())
