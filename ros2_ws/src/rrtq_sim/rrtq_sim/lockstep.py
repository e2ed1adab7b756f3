"""Lock-step bookkeeping: join stamped messages of one simulation step.

Times are integer nanoseconds everywhere in lock-step mode, so that a stamp from one
node compares equal to the same step's stamp from another (no float round-off).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any


def seconds_to_ns(seconds: float) -> int:
    return int(round(seconds * 1e9))


class StampJoin:
    """Collect one message per key and stamp; a stamp completes when every key arrived.

    Sets for stamps older than the last completed one are dropped: they can never be
    used (a late duplicate, or a step the sender abandoned).
    """

    def __init__(self, keys: Iterable[str]) -> None:
        self.keys = frozenset(keys)
        self._pending: dict[int, dict[str, Any]] = {}
        self.last_completed_ns: int | None = None

    def add(self, key: str, stamp_ns: int, value: Any) -> dict[str, Any] | None:
        """Record ``value``; return the key -> value map once ``stamp_ns`` is complete."""
        if key not in self.keys:
            raise KeyError(key)
        if self.last_completed_ns is not None and stamp_ns <= self.last_completed_ns:
            return None
        values = self._pending.setdefault(stamp_ns, {})
        values[key] = value
        if values.keys() != self.keys:
            return None
        self.last_completed_ns = stamp_ns
        self._pending = {s: v for s, v in self._pending.items() if s > stamp_ns}
        return values

    def missing(self, stamp_ns: int) -> frozenset[str]:
        """Keys still awaited for ``stamp_ns``."""
        return self.keys - self._pending.get(stamp_ns, {}).keys()
