"""How the controller flew each run of a bench, from its recording alone (no rclpy).

After the runs, ``rrtq bench`` reads every completed run's recording
(:func:`control_metrics`, in parallel on the bench's workers: :func:`evaluate`) for what
the run's summary cannot say: the median over the last ten legs of each leg's cost
against the true Riccati policy flown through the same disturbance, odometry noise and
actuation delay (:mod:`rrtq_bringup.leg_table`), and against the optimum; the largest
command against the actuator's limit; the guard's reverts and holds. The table
(:func:`aggregate_control`) counts the runs within 5 % and 10 % of the Riccati policy.
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from rrtq_bringup.leg_table import leg_table, summary
from rrtq_bringup.run_data import read_run, recorded_scenario

__all__ = ['control_metrics', 'evaluate', 'aggregate_control']

LAST = 10
"""Legs at the end of a run whose median leg cost is reported."""


def control_metrics(run_dir: str | pathlib.Path) -> dict[str, Any] | None:
    """The controller's figures of one run directory (``run.mcap``), None without legs."""
    mcap = pathlib.Path(run_dir) / 'run.mcap'
    data = read_run(mcap)
    scenario = recorded_scenario(mcap)
    table = summary(leg_table(data, scenario), LAST)
    if not table['legs']:
        return None
    events = [e for _, joined, _ in data.policy_events for e in joined.split(';')]
    limit = float(data.force_limit)
    u_max = float(np.abs(data.cmd_u).max(initial=0.0))
    return {'legs': table['legs'],
            'ratio_riccati_policy_last10': table['median_ratio_riccati_policy_last10'],
            'ratio_optimum_last10': table['median_ratio_last10'],
            'max_abs_force_n': u_max, 'force_limit_n': limit,
            'force_over_limit': u_max / limit if math.isfinite(limit) and limit > 0 else 0.0,
            'reverts': events.count('reverted'), 'holds': events.count('hold')}


def _metrics(directory: str) -> dict[str, Any] | None:
    try:
        return control_metrics(directory)
    except (OSError, ValueError, KeyError) as exc:
        return {'error': f'{type(exc).__name__}: {exc}'}


def evaluate(rows: Sequence[dict[str, Any]], workers: int) -> None:
    """Add ``control`` to every completed row (its ``dir`` read by :func:`control_metrics`)."""
    done = [r for r in rows if r.get('status') == 'completed']
    if not done:
        return
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        for row, metrics in zip(done, pool.map(_metrics, [str(r['dir']) for r in done])):
            row['control'] = metrics


def aggregate_control(rows: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """Over the rows that have ``control``: medians, counts within 5 % and 10 %, the worst force."""
    runs = [r['control'] for r in rows if isinstance(r.get('control'), dict)
            and r['control'].get('ratio_riccati_policy_last10') is not None]
    if not runs:
        return None
    ratios = np.array([c['ratio_riccati_policy_last10'] for c in runs], dtype=float)
    over = np.array([c['force_over_limit'] for c in runs], dtype=float)
    return {'runs': len(runs),
            'ratio_riccati_policy_median': float(np.median(ratios)),
            'ratio_riccati_policy_p90': float(np.percentile(ratios, 90)),
            'within_5pct': int(np.sum(ratios <= 1.05)), 'within_10pct': int(np.sum(ratios <= 1.10)),
            'max_force_over_limit': float(over.max()),
            'beyond_limit': int(np.sum(over > 1.0 + 1e-9)),
            'reverts_holds_median': float(np.median([c['reverts'] + c['holds'] for c in runs]))}
