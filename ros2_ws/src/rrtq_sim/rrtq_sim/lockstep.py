"""Lock-step bookkeeping: join stamped messages of one simulation step.

Times are integer nanoseconds everywhere in lock-step mode, so that a stamp from one
node compares equal to the same step's stamp from another (no float round-off).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
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


@dataclasses.dataclass(frozen=True)
class Requirement:
    """One input a node needs before it may process a step.

    ``key`` must have arrived stamped ``lag`` steps before the step (lag 0: the same
    step; lag 1: the step before, which is what a node downstream in the step's chain
    already produced). When ``names`` is set, the message names (by the stamp returned
    by ``names``) an on-change message of key ``followup`` that must have arrived too:
    a status that says "I published a new plan at this step" holds the step back until
    that plan is here.
    """

    key: str
    lag: int = 0
    followup: str | None = None
    names: Callable[[Any], int] | None = None


class StepInputs:
    """Deliver steps in order, each once its driver message and requirements are in.

    The driver (``/odom``) defines the steps; messages are filed by stamp (ns). Per-step
    messages are kept until their step is delivered; on-change follow-ups are kept by
    stamp, and a delivered step carries the latest follow-up at or before the stamp its
    requirement names.
    """

    def __init__(self, requirements: Sequence[Requirement], dt_ns: int,
                 driver: str = 'odom') -> None:
        self.requirements = tuple(requirements)
        self.dt_ns = dt_ns
        self.driver = driver
        self._steps: dict[str, dict[int, Any]] = {r.key: {} for r in self.requirements}
        self._steps[driver] = {}
        self._followups: dict[str, dict[int, Any]] = {
            r.followup: {} for r in self.requirements if r.followup}
        self.last_delivered: int | None = None

    def add(self, key: str, stamp_ns: int, msg: Any) -> None:
        """File a message (a per-step key, the driver, or a follow-up key); others are
        ignored."""
        if key in self._followups:
            self._followups[key][stamp_ns] = msg
        elif key not in self._steps:
            return                      # not an input of this node in this graph
        elif self.last_delivered is None or stamp_ns > self.last_delivered - self.dt_ns:
            self._steps[key][stamp_ns] = msg

    def pop_ready(self) -> list[dict[str, Any]]:
        """Every step that can now be processed, oldest first (key -> message)."""
        ready = []
        while True:
            # Steps are consecutive from 0: lock-step never skips one.
            stamp = 0 if self.last_delivered is None else self.last_delivered + self.dt_ns
            if stamp not in self._steps[self.driver]:
                return ready
            values = self._collect(stamp)
            if values is None:
                return ready
            named = values.pop('_named', {})
            ready.append(values)
            self.last_delivered = stamp
            self._forget(stamp - self.dt_ns, named)

    def _collect(self, stamp: int) -> dict[str, Any] | None:
        values: dict[str, Any] = {self.driver: self._steps[self.driver][stamp],
                                  'stamp_ns': stamp}
        for req in self.requirements:
            at = stamp - req.lag * self.dt_ns
            if at < 0:
                values[req.key] = None
                continue
            msg = self._steps[req.key].get(at)
            if msg is None:
                return None
            values[req.key] = msg
            if req.followup is not None and req.names is not None:
                named = req.names(msg)
                stored = self._followups[req.followup]
                if named not in stored:
                    return None
                values[req.followup] = stored[named]
                values.setdefault('_named', {})[req.followup] = named
        return values

    def _forget(self, stamp: int, named: dict[str, int]) -> None:
        """Drop per-step messages before ``stamp`` and follow-ups older than the ones
        just named (a status only ever names its latest publication)."""
        for table in self._steps.values():
            for s in [s for s in table if s < stamp]:
                del table[s]
        for key, oldest in named.items():
            table = self._followups[key]
            for s in [s for s in table if s < oldest]:
                del table[s]
