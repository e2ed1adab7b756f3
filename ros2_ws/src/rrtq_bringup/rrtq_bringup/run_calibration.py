"""A run's leg scores as a calibration file next to its recording (``docs/margins.md`` §3, §10).

The score of a leg is its largest deviation D_rob from its straight edge; /safety/status
carries the current leg's largest deviation so far (``leg_deviation``), the count of legs
measured (``legs``) and, under ``learned_bound``, the tube predicted for the leg at its
start (``leg_tube``, 0 for a leg without a model) and whether that tube rested on a level
residuals had raised (``leg_refuted``), so the scores are read off the recording: the last
``leg_deviation`` of each leg, and learned_bound's three categories (deviation / tube where
there was a tube, by its level; the raw deviation where there was none). A run
started from a calibration (``safety.calibration``) writes the old scores followed by its
own, as a robot carries its calibration from mission to mission; ``rrtq bench`` pools its
runs' own scores (:func:`recorded_calibration`) into one file.
"""

from __future__ import annotations

import datetime
import pathlib

from rrtq_bringup.run_data import messages, safety_legs
from rrtq_bringup.scenario import Scenario
from rrtq_common import topics
from rrtq_planner.margins.calibration import Calibration, read_calibration, write_calibration

__all__ = ['CALIBRATION_FILE', 'recorded_calibration', 'write_run_calibration']

CALIBRATION_FILE = 'calibration.json'


def recorded_calibration(recording: str | pathlib.Path, source: str = '',
                         created: str = '') -> Calibration:
    """The run's own scores: raw, and learned_bound's normalized, refuted and prior categories.

    A recording older than ``leg_refuted`` counts every leg with a tube as normalized.
    """
    statuses = [s for s in messages(recording, topics.SAFETY_STATUS) if s.legs > 0]
    learned = any(s.margin_mode == 'learned_bound' for s in statuses)
    ordered = [(leg.deviation, leg.tube, bool(leg.refuted)) for leg in safety_legs(statuses)]
    legs = ordered if learned else []
    return Calibration(tuple(d for d, _, _ in ordered), source, created,
                       tuple(d / tube for d, tube, up in legs if tube > 0.0 and not up),
                       tuple(d for d, tube, _ in legs if tube <= 0.0),
                       tuple(d / tube for d, tube, up in legs if tube > 0.0 and up))


def write_run_calibration(scenario: Scenario, recording: pathlib.Path) -> pathlib.Path:
    """Write ``calibration.json`` beside ``recording``: the scenario's calibration, then this run's."""
    base = (read_calibration(scenario.margins.calibration) if scenario.margins.calibration
            else Calibration(()))
    created = datetime.datetime.now(datetime.UTC).strftime('%Y-%m-%dT%H:%M:%SZ')
    out = recording.parent / CALIBRATION_FILE
    own = recorded_calibration(recording)
    write_calibration(out, base.extended(own.scores, f'{scenario.name} seed {scenario.seed}',
                                         created, own.normalized, own.prior, own.refuted))
    return out
