"""M. Otte's obstacle-file format (RRT^X's environments): the one reader, and a writer.

Layout: the polygon count P; per polygon its vertex count N then N lines ``x, y``;
"discoverable" files add a flag line (-1, 0 or 1) after each polygon (0: static and
known; 1: unknown until sensed; -1: believed but absent).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence

import numpy as np

from rrtq_common.geometry import as_polygon

__all__ = ['load_otte', 'read_polygons', 'write_otte']

_INT_RE = re.compile(r'^[+-]?\d+$')


def _split_pair(text: str) -> tuple[float, float] | None:
    parts = [p for p in re.split(r'[,\s]+', text.strip()) if p]
    if len(parts) != 2:
        return None
    try:
        x, y = float(parts[0]), float(parts[1])
    except ValueError:
        return None
    if not (math.isfinite(x) and math.isfinite(y)):
        return None
    return x, y


def load_otte(path: str | os.PathLike[str]) -> list[tuple[np.ndarray, int | None]]:
    """Parse an obstacle file in M. Otte's RRT^X format.

    Layout: the polygon count P; per polygon its vertex count N then N lines ``x, y``;
    "discoverable" files add a flag line (-1, 0 or 1) after each polygon.  A flag can
    never be mistaken for the next vertex count because a polygon needs N >= 3, so the
    line after the first polygon decides whether the file carries flags.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    list of (numpy.ndarray, int or None)
        Each polygon ``(k, 2)`` with a repeated closing vertex dropped, and its flag
        (None when the file has no flags).

    Raises
    ------
    ValueError
        On malformed content, naming the file and 1-based line number.
    OSError
        If the file cannot be read.
    """
    with open(path, encoding='utf-8') as fh:
        raw = fh.read().splitlines()
    # (line number, text) of the non-blank lines; numbers stay those of the file.
    lines = [(i + 1, s.strip()) for i, s in enumerate(raw) if s.strip()]
    pos = 0

    def fail(msg: str, at: int | None = None) -> ValueError:
        if at is None:
            at = lines[pos][0] if pos < len(lines) else (len(raw) + 1)
        return ValueError(f'{os.fspath(path)}:{at}: {msg}')

    def read_int(what: str) -> int:
        nonlocal pos
        if pos >= len(lines):
            raise fail(f'unexpected end of file, expected {what}')
        num, text = lines[pos]
        if not _INT_RE.match(text):
            raise fail(f'expected {what} (an integer), got {text!r}', num)
        pos += 1
        return int(text)

    count = read_int('the number of polygons')
    if count < 0:
        raise fail('the number of polygons must be >= 0', lines[0][0])
    has_flags: bool | None = None
    result: list[tuple[np.ndarray, int | None]] = []
    for index in range(count):
        start_line = lines[pos][0] if pos < len(lines) else len(raw) + 1
        k = read_int(f'the vertex count of polygon {index}')
        if k < 3:
            raise fail(f'polygon {index} has {k} vertices, needs at least 3', start_line)
        verts = []
        for _ in range(k):
            if pos >= len(lines):
                raise fail(f'unexpected end of file inside polygon {index}')
            num, text = lines[pos]
            pair = _split_pair(text)
            if pair is None:
                raise fail(f"expected a vertex 'x, y', got {text!r}", num)
            verts.append(pair)
            pos += 1
        if has_flags is None:
            has_flags = _next_is_flag(lines, pos, count - index - 1)
        flag: int | None = None
        if has_flags:
            flag_line = lines[pos][0] if pos < len(lines) else len(raw) + 1
            flag = read_int(f'the flag of polygon {index}')
            if flag not in (-1, 0, 1):
                raise fail(f'flag must be -1, 0 or 1, got {flag}', flag_line)
        poly = np.array(verts, dtype=float)
        if len(poly) > 3 and np.array_equal(poly[0], poly[-1]):
            poly = poly[:-1]
        try:
            poly = as_polygon(poly)
        except ValueError as exc:
            raise fail(f'polygon {index}: {exc}', start_line) from None
        result.append((poly, flag))
    if pos < len(lines):
        raise fail(f'unexpected content after {count} polygons: {lines[pos][1]!r}')
    return result


def _next_is_flag(lines: list[tuple[int, str]], pos: int, remaining: int) -> bool:
    """Decide from the line after the first polygon whether the file has flags."""
    if pos >= len(lines):
        return False
    text = lines[pos][1]
    if not _INT_RE.match(text):
        return False  # let the regular parser report the bad line
    value = int(text)
    if remaining == 0:
        return True  # something after the last polygon can only be its flag
    return value in (-1, 0, 1)


def read_polygons(path: str | os.PathLike[str]) -> list[np.ndarray]:
    """The polygons of an Otte file, whatever their flags."""
    return [poly for poly, _ in load_otte(path)]


def write_otte(path: str | os.PathLike[str], polygons: Sequence[np.ndarray]) -> None:
    """Write polygons in Otte's format (closing vertex repeated, flag 0: known)."""
    lines = [str(len(polygons))]
    for poly in polygons:
        lines.append(str(len(poly) + 1))
        lines += [f'{x:.6f}, {y:.6f}' for x, y in np.vstack((poly, poly[:1]))]
        lines.append('0')
    with open(path, 'w', encoding='utf-8') as fh:
        fh.write('\n'.join(lines) + '\n')
