"""Calibration files: the leg scores a run carries to the next (``docs/margins.md`` §2).

One mission has 15-35 legs while the conformal quantile at δ = 0.05 needs 19 scores, so a
run writes its scores next to its recording and a later run starts from them, as a robot
carries its calibration from mission to mission. The file is JSON::

    {"format": "rrtq-margin-calibration", "version": 1,
     "scores": [0.41, 0.37, ...],        # m, largest deviation of each leg, oldest first
     "source": "rrtqx-paper seed 7",      # free text: where the scores come from
     "created": "2026-12-01T17:27:00Z"}   # free text, given by the writer

Unknown keys are an error (a newer writer's file is not silently half-read); a later
version changes ``version``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import pathlib
from collections.abc import Iterable

__all__ = ['FORMAT', 'VERSION', 'Calibration', 'read_calibration', 'write_calibration']

FORMAT = 'rrtq-margin-calibration'
VERSION = 1
_KEYS = {'format', 'version', 'scores', 'source', 'created'}


@dataclasses.dataclass(frozen=True)
class Calibration:
    """Leg scores of earlier runs, oldest first."""

    scores: tuple[float, ...]
    """m: each leg's largest deviation D_rob from its straight edge."""
    source: str = ''
    created: str = ''

    def __post_init__(self) -> None:
        for s in self.scores:
            if not (isinstance(s, (int, float)) and not isinstance(s, bool)
                    and math.isfinite(s) and s >= 0.0):
                raise ValueError(f'a score must be a finite number >= 0, got {s!r}')

    def extended(self, scores: Iterable[float], source: str = '', created: str = '') -> Calibration:
        """These scores followed by a newer run's (what that run writes)."""
        return Calibration(self.scores + tuple(float(s) for s in scores),
                           source or self.source, created or self.created)


def write_calibration(path: str | pathlib.Path, calibration: Calibration) -> None:
    """Write ``calibration`` to ``path`` (JSON, version :data:`VERSION`)."""
    data = {'format': FORMAT, 'version': VERSION, 'scores': list(calibration.scores),
            'source': calibration.source, 'created': calibration.created}
    pathlib.Path(path).write_text(json.dumps(data, indent=1) + '\n')


def read_calibration(path: str | pathlib.Path) -> Calibration:
    """Read a calibration file; a bad one raises ValueError naming the file and the key."""
    p = pathlib.Path(path)
    try:
        data = json.loads(p.read_text())
    except OSError as exc:
        raise ValueError(f'{p}: cannot read the calibration file ({exc.strerror})') from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f'{p}: not a JSON calibration file ({exc})') from exc
    if not isinstance(data, dict):
        raise ValueError(f'{p}: a calibration file is a JSON object, got {type(data).__name__}')
    if data.get('format') != FORMAT:
        raise ValueError(f'{p}: format must be {FORMAT!r}, got {data.get("format")!r}')
    if data.get('version') != VERSION:
        raise ValueError(f'{p}: version {data.get("version")!r} is not supported '
                         f'(this reader knows version {VERSION})')
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise ValueError(f'{p}: unknown key {unknown[0]!r}')
    scores = data.get('scores')
    if not isinstance(scores, list):
        raise ValueError(f'{p}: scores must be a list of numbers (m)')
    for key in ('source', 'created'):
        if not isinstance(data.get(key, ''), str):
            raise ValueError(f'{p}: {key} must be a string')
    try:
        return Calibration(tuple(scores), data.get('source', ''), data.get('created', ''))
    except ValueError as exc:
        raise ValueError(f'{p}: scores: {exc}') from exc
