"""Calibration files: the leg scores a run carries to the next (``docs/margins.md`` §3, §10).

One mission has 15-35 legs while the conformal quantile at δ = 0.05 needs 19 scores, so a
run writes its scores next to its recording, ``rrtq bench`` pools its runs' into one file,
and a later run starts from it, as a robot carries its calibration from mission to mission.
The file is JSON::

    {"format": "rrtq-margin-calibration", "version": 3,
     "scores": [0.41, 0.37, ...],        # m, largest deviation of each leg, oldest first
     "normalized": [0.62, 0.18, ...],    # learned_bound: deviation / predicted tube of each
                                         # leg that had a contracting model at its start,
                                         # its tube at the prior bound
     "refuted": [0.21, ...],             # the same, its tube on a level residuals raised
     "prior": [0.35, ...],               # learned_bound: m, deviation of each leg without one
     "source": "rrtqx-paper seed 7",     # free text: where the scores come from
     "created": "2026-12-01T17:27:00Z"}  # free text, given by the writer

``scores`` is what ``conformal`` calibrates on; ``normalized``, ``refuted`` and ``prior``
are ``learned_bound``'s three Mondrian categories (the legs with a model, scored against
their tube, by the level it rests on; the first legs, before the model contracts, scored
raw). Version 1 files (``scores`` only) are read with the others empty; version 2 files
(no ``refuted``: their ``normalized`` holds every leg with a model) with ``refuted`` empty.
Unknown keys are an error (a newer writer's file is not silently half-read); a later
version changes ``version``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import pathlib
from collections.abc import Iterable

__all__ = ['FORMAT', 'VERSION', 'Calibration', 'read_calibration', 'write_calibration',
           'pooled']

FORMAT = 'rrtq-margin-calibration'
VERSION = 3
_LISTS = ('scores', 'normalized', 'refuted', 'prior')
_KEYS = {'format', 'version', 'source', 'created', *_LISTS}
_SINCE = {'normalized': 2, 'prior': 2, 'refuted': 3}
"""The version that added each key (a file of an older version holding it is an error)."""


@dataclasses.dataclass(frozen=True)
class Calibration:
    """Leg scores of earlier runs, oldest first."""

    scores: tuple[float, ...]
    """m: each leg's largest deviation D_rob from its straight edge."""
    source: str = ''
    created: str = ''
    normalized: tuple[float, ...] = ()
    """learned_bound: each leg's largest deviation over the tube predicted for it at its start
    (legs that started with a contracting model)."""
    prior: tuple[float, ...] = ()
    """learned_bound, m: the largest deviation of each leg that started without one."""
    refuted: tuple[float, ...] = ()
    """learned_bound: as ``normalized``, for the legs whose tube rested on a level that
    residuals had raised above the prior bound."""

    def __post_init__(self) -> None:
        for key in _LISTS:
            for s in getattr(self, key):
                if not (isinstance(s, (int, float)) and not isinstance(s, bool)
                        and math.isfinite(s) and s >= 0.0):
                    raise ValueError(f'{key}: a score must be a finite number >= 0, got {s!r}')

    def extended(self, scores: Iterable[float], source: str = '', created: str = '',
                 normalized: Iterable[float] = (), prior: Iterable[float] = (),
                 refuted: Iterable[float] = ()) -> Calibration:
        """These scores followed by a newer run's (what that run writes)."""
        return Calibration(self.scores + tuple(float(s) for s in scores),
                           source or self.source, created or self.created,
                           self.normalized + tuple(float(s) for s in normalized),
                           self.prior + tuple(float(s) for s in prior),
                           self.refuted + tuple(float(s) for s in refuted))


def pooled(calibrations: Iterable[Calibration], source: str = '',
           created: str = '') -> Calibration:
    """One calibration holding every given one's scores, in the given order."""
    out = Calibration((), source, created)
    for c in calibrations:
        out = out.extended(c.scores, source, created, c.normalized, c.prior, c.refuted)
    return out


def write_calibration(path: str | pathlib.Path, calibration: Calibration) -> None:
    """Write ``calibration`` to ``path`` (JSON, version :data:`VERSION`)."""
    data = {'format': FORMAT, 'version': VERSION, 'scores': list(calibration.scores),
            'normalized': list(calibration.normalized), 'refuted': list(calibration.refuted),
            'prior': list(calibration.prior),
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
    version = data.get('version')
    if isinstance(version, bool) or version not in range(1, VERSION + 1):
        raise ValueError(f'{p}: version {version!r} is not supported '
                         f'(this reader knows version {VERSION})')
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise ValueError(f'{p}: unknown key {unknown[0]!r}')
    newer = sorted(k for k in set(data) & set(_SINCE) if _SINCE[k] > data['version'])
    if newer:
        raise ValueError(f'{p}: unknown key {newer[0]!r} in a version {version} file')
    lists = {}
    for key in _LISTS:
        value = data.get(key, [] if key != 'scores' else None)
        if not isinstance(value, list):
            raise ValueError(f'{p}: {key} must be a list of numbers')
        lists[key] = tuple(value)
    for key in ('source', 'created'):
        if not isinstance(data.get(key, ''), str):
            raise ValueError(f'{p}: {key} must be a string')
    try:
        return Calibration(lists['scores'], data.get('source', ''), data.get('created', ''),
                           lists['normalized'], lists['prior'], lists['refuted'])
    except ValueError as exc:
        raise ValueError(f'{p}: {exc}') from exc
