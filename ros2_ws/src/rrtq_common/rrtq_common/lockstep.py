"""The lock-step gate: every node's inputs, step by step (no rclpy).

Times are integer nanoseconds everywhere in lock-step mode, so that a stamp from one
node compares equal to the same step's stamp from another (no float round-off).

A node hands every message it receives to its :class:`StepGate`
(:func:`rrtq_common.inputs.subscribe_inputs`) and processes the steps the gate hands it.
The gate is the one place that knows the modes: lock-step (a step is ready once its
driver message and its :class:`Requirement` s are in, steps in order), paced (every
driver message is a step, with the latest of every other input), and a resent step (the
simulator republishes its odometry when acknowledgements stall: the node's last answer
goes out again, unchanged).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Generic, TypeVar

__all__ = ['seconds_to_ns', 'StampJoin', 'Requirement', 'StepInputs', 'Step', 'StepGate',
           'OnChange']

T = TypeVar('T')


def seconds_to_ns(seconds: float) -> int:
    """Seconds as integer nanoseconds (the stamps of lock-step)."""
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
    that plan is here. ``every``: the input comes on every ``every``-th step only (steps
    0, every, 2 every...: a scan at a lower rate than the steps); on the others the step
    carries None for it.
    """

    key: str
    lag: int = 0
    followup: str | None = None
    names: Callable[[Any], int] | None = None
    every: int = 1


@dataclasses.dataclass(frozen=True)
class Step:
    """One step's inputs: key -> message (None for a requirement before the first step)."""

    stamp_ns: int
    messages: Mapping[str, Any]

    def __getitem__(self, key: str) -> Any:
        return self.messages[key]

    def get(self, key: str) -> Any:
        """The message of ``key``, or None."""
        return self.messages.get(key)


@dataclasses.dataclass(frozen=True)
class OnChange(Generic[T]):
    """An input published on change: the stamp it was published at, read on demand.

    A core compares the stamp with the last one it took and reads (converts) the
    content only when it changed.
    """

    stamp_ns: int
    read: Callable[[], T]


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
        """File a message (a per-step key, the driver, or a follow-up key).

        Messages of other keys are ignored: they are not inputs of this node.
        """
        if key in self._followups:
            self._followups[key][stamp_ns] = msg
        elif key not in self._steps:
            return                      # not an input of this node in this graph
        elif self.last_delivered is None or stamp_ns > self.last_delivered - self.dt_ns:
            self._steps[key][stamp_ns] = msg

    def pop_ready(self) -> list[dict[str, Any]]:
        """Every step that can now be processed, oldest first (key -> message)."""
        ready: list[dict[str, Any]] = []
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
            if at < 0 or (req.every > 1 and round(at / self.dt_ns) % req.every):
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
        """Drop per-step messages before ``stamp``, and follow-ups older than those named.

        A status only ever names its latest publication.
        """
        for table in self._steps.values():
            for s in [s for s in table if s < stamp]:
                del table[s]
        for key, oldest in named.items():
            table = self._followups[key]
            for s in [s for s in table if s < oldest]:
                del table[s]


class StepGate:
    """A node's inputs, whatever the mode: what to process, and what to answer again.

    Parameters
    ----------
    requirements : sequence of Requirement
        What a lock-step step waits for besides its driver message.
    lockstep : bool
        False: paced, every driver message is a step with the latest of every input.
    driver : str or None
        Key of the message that defines the steps (None: a step is a stamp its
        requirements complete, as the simulator's acknowledgements of its own steps).
    ordered : bool
        Lock-step steps come in order, each after the one before (:class:`StepInputs`);
        False: each stamp as soon as its messages of every key are in (:class:`StampJoin`:
        the same-step joins of the simulator and the disturbance injector, lag 0 only).
    dt_ns : int
        The step, ns (ordered steps).
    resend : callable, optional
        Publishes an answer again: called with the messages given to :meth:`answered`
        when a driver message repeats a step already answered.
    on_step : callable, optional
        Processes a step: called with each step as it becomes ready (else the node takes
        them with :meth:`ready`).
    held : bool
        Keep the steps until :meth:`release` (a node that cannot process them yet; paced,
        only the latest step is kept).
    """

    def __init__(self, requirements: Sequence[Requirement], *, lockstep: bool,
                 driver: str | None = 'odom', ordered: bool = True, dt_ns: int = 0,
                 resend: Callable[..., None] | None = None,
                 on_step: Callable[[Step], None] | None = None, held: bool = False) -> None:
        self.lockstep = lockstep
        self.on_step = on_step
        self.held = held
        self.driver = driver
        self.latest: dict[str, Any] = {}
        self._inputs: StepInputs | None = None
        self._join: StampJoin | None = None
        if ordered:
            if driver is None or dt_ns <= 0:
                raise ValueError('ordered steps need a driver message and a step')
            self._inputs = StepInputs(requirements, dt_ns, driver)
        else:
            self._join = StampJoin([r.key for r in requirements] + ([driver] if driver else []))
        self._ready: list[Step] = []
        self._resend = resend
        self._answer: tuple[int, tuple[Any, ...]] | None = None

    def add(self, key: str, stamp_ns: int, msg: Any) -> None:
        """File a message, then hand every step that is ready to ``on_step``.

        A driver message of a step already answered is answered again (``resend``).
        """
        self._file(key, stamp_ns, msg)
        self._deliver()

    def release(self) -> None:
        """Stop holding the steps: hand the ready ones to ``on_step``, and all to come."""
        self.held = False
        self._deliver()

    def _deliver(self) -> None:
        if self.on_step is not None and not self.held:
            for step in self.ready():
                self.on_step(step)

    def _file(self, key: str, stamp_ns: int, msg: Any) -> None:
        if key == self.driver and self._answer is not None and stamp_ns <= self._answer[0]:
            if self._resend is not None:
                self._resend(*self._answer[1])
            return
        if not self.lockstep:
            self.latest[key] = msg
            if self.driver is None or key == self.driver:
                step = Step(stamp_ns, {key: msg} if self.driver is None else dict(self.latest))
                # Paced, a held step is superseded by the next: only the latest counts.
                self._ready = [step] if self.held else [*self._ready, step]
        elif self._join is not None:
            if key in self._join.keys:
                done = self._join.add(key, stamp_ns, msg)
                if done is not None:
                    self._ready.append(Step(stamp_ns, done))
        else:
            assert self._inputs is not None
            self._inputs.add(key, stamp_ns, msg)

    def ready(self) -> list[Step]:
        """The steps that can be processed now, oldest first."""
        if self._inputs is not None and self.lockstep:
            for values in self._inputs.pop_ready():
                stamp = values.pop('stamp_ns')
                self._ready.append(Step(stamp, values))
        ready, self._ready = self._ready, []
        return ready

    def answered(self, stamp_ns: int, *messages: Any) -> None:
        """Record the answer to step ``stamp_ns`` (what a resent step gets again)."""
        self._answer = (stamp_ns, messages)

    def missing(self, stamp_ns: int) -> frozenset[str]:
        """Joined lock-step (``ordered=False``): the keys still awaited for ``stamp_ns``."""
        assert self._join is not None
        return self._join.missing(stamp_ns)
