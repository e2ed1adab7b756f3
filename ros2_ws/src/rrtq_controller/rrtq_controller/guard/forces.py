"""The guard's forces: the safe hold's brake and the keep-offs from obstacles.

Both act on the measured velocity with no model of the plant, and adapt their force on
line from what the last step did (:class:`Brake`, :class:`KeepOff`); :class:`Sensing` is
what their rules allow for (odometry noise, actuation delay), at the guard's false-alarm
rate :data:`.policy.FALSE_ALARM`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm

from .policy import FALSE_ALARM

Array = NDArray[np.float64]

Z_FALSE_ALARM = float(norm.ppf(1.0 - FALSE_ALARM))
"""The one-sided normal quantile at :data:`.policy.FALSE_ALARM`."""
_RAYLEIGH = math.sqrt(2.0 * math.log(1.0 / FALSE_ALARM))
"""The Rayleigh quantile (in σ) that a 2-D normal's norm exceeds with probability FALSE_ALARM."""


@dataclass
class Sensing:
    """What the on-line rules of :class:`Brake` and :class:`KeepOff` must allow for.

    Those rules judge what the last force did from the measured velocity: did the speed fall
    fast enough, did the motion reverse, is the robot at rest. Two things of a real robot
    blur that judgement: odometry noise (σ_v m/s per axis, the odometry's covariance) and
    actuation delay (a force acts ``dead_steps`` steps after it is commanded; the observer
    identifies it, :attr:`rrtq_controller.observer.OneStepModel.delay`). So the rules compare
    speeds :attr:`lag` = 1 + ``dead_steps`` steps apart (the first step a change can show),
    change a force at most once per lag, and call an effect only where it stands out of
    the noise at the false-alarm rate :data:`FALSE_ALARM` (a one-sided normal quantile on
    the difference of two speeds, σ_v √2; a Rayleigh quantile for a speed at rest). With
    exact, instant odometry (the defaults of the simulator) every allowance is zero and
    the rules are the step-to-step ones of before.
    """

    velocity_std: float = 0.0
    """σ_v, m/s per axis."""
    dead_steps: int = 0
    """Steps a commanded force takes to act."""
    step_gain: float = 0.0
    """m/s per N: the most a force held over one step changes the velocity (the velocity
    rows of the observer's Γ, its largest singular value); 0: not known yet."""

    @property
    def lag(self) -> int:
        """Steps between the speeds a rule compares."""
        return 1 + max(int(self.dead_steps), 0)

    @property
    def difference(self) -> float:
        """m/s: how much one speed may exceed another by noise alone (at the false-alarm rate)."""
        return Z_FALSE_ALARM * math.sqrt(2.0) * self.velocity_std

    def rest(self, floor: float, samples: int = 1) -> float:
        """m/s: the speed below which a robot counts as at rest (a speed noise can make).

        ``floor`` with exact odometry; with noise, at least the speed a robot at rest shows
        with probability :data:`FALSE_ALARM` (|n| of a 2-D normal is Rayleigh:
        P(|n| > r) = exp(-r² / 2σ_v²)), for the mean of ``samples`` readings (σ_v / √samples).
        """
        std = self.velocity_std / math.sqrt(max(int(samples), 1))
        return max(floor, std * _RAYLEIGH)

    def samples_for(self, floor: float) -> int:
        """The fewest readings whose mean tells rest at ``floor``: its :meth:`rest` is ``floor``.

        1 with exact odometry. A single noisy reading calls a robot at rest below the
        Rayleigh quantile of the noise (0.15 m/s at σ_v = 0.05 m/s, α = 1 %), where a robot
        moving at 0.2 m/s reads on some of its steps; the mean of k readings brings that
        quantile down by √k, to the floor at k = (σ_v q / floor)².
        """
        if floor <= 0.0 or self.velocity_std <= 0.0:
            return 1
        return max(1, math.ceil((self.velocity_std * _RAYLEIGH / floor) ** 2 - 1e-9))

    def resolved(self, force: float, unknown: float) -> float:
        """m/s: the speed one step of ``force`` (N) changes.

        Below it a force cannot tell rest from motion; ``unknown`` until the observer
        knows the input gain.
        """
        return self.step_gain * force if self.step_gain > 0.0 else unknown


def slowing_too_little(speed: float, before: float, dt: float, stop_time: float,
                       rest_speed: float, allowance: float = 0.0) -> bool:
    """Whether a speed that was ``before`` one interval ``dt`` ago fell too little to stop in ``stop_time``.

    The rule by which :class:`Brake` and :class:`KeepOff` double their force: above
    ``rest_speed``, the speed must fall by at least speed Δt / ``stop_time`` per step; it
    is called too little only by more than ``allowance`` (m/s, :attr:`Sensing.difference`).
    """
    return speed > rest_speed and speed > before * (1.0 - dt / stop_time) + allowance


@dataclass
class Brake:
    """The safe hold: a bounded force against the measured velocity, adapted on line.

    Where no policy has completed a leg there is no policy known to work, and the initial
    policy is no safe hold when it is the zero gain: a lightly damped robot (110 kg,
    15 kg/s: a 7 s time constant) coasts on at the speed that tripped the watch, into
    whatever lies ahead. The brake commands u = -F v / |v| with v = x̄[2:4], the velocity
    of the position (the state layout the watch's speed bound already uses), and adapts
    the force F from what the last step did, with no model of the plant:

    * F starts at the force :meth:`start` is given (the probing scale, or the forces the
      robot has already been pushed with), capped at ``limit``;
    * when the speed did not fall by at least |v| Δt / ``stop_time`` over the last step
      (braking too weakly to stop within ``stop_time``), F doubles, up to ``limit``;
    * when the velocity reversed (v · v_prev < 0 between any two consecutive steps since the
      last change: a step overshot rest), F halves.

    Every command is within ``limit`` per axis (|u_i| <= F <= limit). The brake removes
    kinetic energy wherever a force along -v decelerates the robot (vᵀ B_v v > 0 for the
    velocity rows B_v of B, as on the rover family, B_v = I/m); overshooting rest in one
    step halves F, so F falls geometrically until a step no longer overshoots. Below the
    rest speed the force is proportional to the speed (no full push in the direction of
    sensor noise), and the robot is at rest: the larger of the speed odometry noise can
    show and the speed one step of F changes (:meth:`Sensing.resolved`, from the
    observer's input gain; ``rest_speed`` until it is known). Beyond the papers, like the
    rest of this module.
    """

    limit: float
    stop_time: float
    dt: float
    rest_speed: float = 0.05
    force: float = 0.0
    prev: Array | None = None
    at_rest: bool = False
    """Whether the speed was at most the rest speed at the last step."""
    sensing: Sensing = field(default_factory=Sensing)
    """Odometry noise and actuation delay the rules allow for (:class:`Sensing`)."""
    _recent: deque[Array] = field(default_factory=deque)
    _wait: int = 0

    def start(self, force: float) -> None:
        """A new hold from ``force`` (N), no previous velocity."""
        self.force = min(force, self.limit)
        self.prev = None
        self.at_rest = False
        self._recent.clear()
        self._wait = 0

    def __call__(self, x: Array, m: int) -> Array:
        """The braking force (m,) for the state x̄; zero when x̄ has no velocity part."""
        x = np.asarray(x, dtype=float)
        if x.size < 2 + m:
            return np.zeros(m)
        v = x[2:2 + m]
        speed = float(np.linalg.norm(v))
        # at rest: slower than noise shows, and than one step of the brake's force changes
        sense = self.sensing
        rest = sense.rest(sense.resolved(self.force, self.rest_speed))
        lag = sense.lag
        self._recent.append(v.copy())
        while len(self._recent) > lag + 1:
            self._recent.popleft()
        if self._wait > 0:
            self._wait -= 1               # the last change has not shown yet
        elif len(self._recent) > lag:
            then = self._recent[0]        # lag steps ago
            before = float(np.linalg.norm(then))
            noise = sense.difference
            floor = noise / math.sqrt(2.0)
            if (float(v @ then) < 0.0 and min(speed, before) > floor) or _flipped(self._recent, max(floor, rest)):
                self.force *= 0.5
                self._wait = lag - 1
            elif slowing_too_little(speed, before, lag * self.dt, self.stop_time, rest, noise):
                self.force = min(2.0 * self.force, self.limit)
                self._wait = lag - 1
        self.prev = v.copy()
        self.at_rest = speed <= rest
        return np.asarray(-self.force * v / max(speed, rest), dtype=float)


def _flipped(recent: deque[Array], floor: float) -> bool:
    """Whether the velocity reversed between two consecutive steps of ``recent``, both faster than ``floor``.

    The caller's ``floor`` is the brake's rest speed (or the noise's, if larger): a sign
    change at rest is the push or the noise jittering a robot that stands, not an overshoot
    (counting those halved the force on every jitter of a robot held under a white push).

    An overshoot of rest, whatever the delay: comparing only speeds ``lag`` steps apart, a
    brake that overshot every step (a velocity alternating in sign, with an even lag the
    same sign as ``lag`` steps ago) never saw a reversal and doubled its force to the limit
    instead: until the observer identifies the delay the brake allows for the longest it
    can identify (3 steps), and on a robot without a delay it went to ±1000 N at the
    period of two steps (white 1 m/s², seed 6 of the robot-side row).
    """
    items = list(recent)
    return any(float(a @ b) < 0.0 and min(float(np.linalg.norm(a)), float(np.linalg.norm(b))) > floor
               for a, b in zip(items[:-1], items[1:], strict=True))


@dataclass
class KeepOff:
    """Stops an approach to a detected obstacle: a push away from it, adapted on line.

    The plan keeps the robot's *line* clear by the margin; the robot itself may still come
    near an obstacle: after a brake that stopped it a few cm away (the margin grew past
    where it stood, and the next plan from there skirts the obstacle), or when a learning
    policy drifts. Like Nav2's collision monitor, which slows or stops a robot whose
    footprint nears an obstacle, this acts on the robot's map (the safety node's nearest
    *detected* obstacle: its distance c from the robot's disc and the unit vector n from
    it to the robot), never on the truth, and with no model of the plant:

    * within ``zone`` of the obstacle the command has no component toward it (its part
      along n is raised to at least 0), and while the robot approaches it (a = -v · n > 0)
      to at least +F, a push away; the tangential part of the command, and any stronger
      push away, are left alone;
    * F starts at the force ``scale()`` gives when an engagement starts (the probing scale,
      or the forces the robot has been pushed with) and doubles, up to ``limit``, while the approach speed
      does not fall fast enough to stop within the time to contact c / a; it halves when
      the approach has reversed (the robot moves away: no push then), and the push is
      proportional to a below the speed odometry noise can show (:meth:`Sensing.rest`: no
      full push at sensor noise; with exact odometry any approach is answered in full:
      a robot creeping in at 0.02 m/s under a steady push once touched an obstacle), and in
      full, at twice the force, where the mean approach speed over the steps in the zone
      (since it entered, or since the last creep found) shows a creep that single speeds
      cannot (:meth:`_creeping`);
    * ahead of the zone, within ``lead`` seconds of it at the approach speed (from
      ``zone`` out to ``zone`` + ``lead`` a), it looks ahead, as Nav2's collision monitor
      does with its time before collision, when the robot heads at the obstacle (within
      45° of its direction; obliquely it mostly slides past a corner the plan skirts: looking
      ahead on every approach, it acted in 13 of 20 paper-plant runs and one run's last-ten
      leg cost rose to 1.051, against 9 runs and at most 1.019 with the 45° rule): the
      command is left alone while the approach
      slows fast enough to stop before the zone (a deceleration of at least a² / 2g, g
      the gap to the zone, or per step a fall of a Δt / (2 g / a)), and once it does not,
      the push starts from ``scale()`` there and doubles by the same rule. A
      heavy robot cannot stop within the zone from the speed it may enter it at (120 kg at
      150 N stops from 0.8 m/s in 0.26 m at the limit, and the push ramps up from the
      probing scale first: seen touching an obstacle 5 mm deep);
    * once the observer knows the input gain (:attr:`Sensing.step_gain`), also as far ahead as the
      push at its fastest needs to stop the approach (:meth:`stop_distance`, from the
      speed it will have at the zone under the steady push, :meth:`entry_speed`), and
      however oblique the approach, where the zone alone cannot stop it or where it is
      pushing already (it holds on through an approach that turns oblique under its push,
      rather than letting go and taking the robot again in the zone): a 110 kg rover at
      200 N crossed the world's boundary by 0.018 m, 47° off head-on at 0.93 m/s under a
      55 N diagonal sinusoid, and by 0.09 m head-on at 5 m/s (it needs 7 m to stop; a
      second ahead is 5 m). On the 40 kg rover at 1000 N the zone stops any approach up to
      1.6 m/s, and a second ahead is farther than it needs below 50 m/s;
    * outside the zone and its lead nothing is changed.

    The push removes approach speed wherever a force along n accelerates the robot along
    n (nᵀ B_v n > 0, as on the rover family). Beyond the papers, like the rest of this
    module. The Bellman rows use the force applied, so learning stays consistent.
    """

    zone: float
    limit: float
    dt: float
    lead: float = 0.0
    """s: how far ahead of the zone, in time at the approach speed, the approach is watched."""
    force: float = 0.0
    prev: float | None = None
    """The approach speed a at the last pushing step (None: not pushing)."""
    push: float = 0.0
    """N: how much the last step raised the command along n (0: not acting)."""
    normal: Array | None = None
    """The unit vector n (from the obstacle to the robot) it pushed along on the last step
    (None: it did not push)."""
    sensing: Sensing = field(default_factory=Sensing)
    """Odometry noise and actuation delay the rules allow for (:class:`Sensing`)."""
    _recent: deque[float] = field(default_factory=deque)
    _wait: int = 0
    _creep: deque[float] = field(default_factory=deque)
    """The approach speeds of the steps in the zone, over the last ``lead`` (the creep test)."""
    _full: int = 0
    """Steps left of the full push a creep found (not scaled down to the speed noise can show)."""

    head_on: float = math.cos(math.pi / 4.0)
    """The look-ahead is for approaches within 45° of head-on (a >= this |v|), and for any
    approach the zone cannot stop (:meth:`stop_distance`; without the input gain,
    :attr:`Sensing.step_gain`, ``lead`` and this rule alone)."""

    def reach(self, velocity: Array, direction: Array) -> float:
        """m: the distance within which it acts, ``zone`` + ``lead`` times the approach speed.

        Only for a head-on approach: a robot moving obliquely toward the nearest point of an
        obstacle mostly slides past it (a corner the plan skirts), and the zone alone
        answers the approach component it does have.
        """
        n = np.asarray(direction, dtype=float)
        v = np.asarray(velocity, dtype=float)[:n.size]
        a = -float(v @ n)
        if self.zone <= 0.0 or a < self.head_on * float(np.linalg.norm(v)):
            return self.zone                       # off (no zone), or not head-on
        return self.zone + self.lead * a

    def __call__(self, u: Array, velocity: Array, distance: float, direction: Array,
                 scale: Callable[[], float], steady: Array | None = None) -> Array:
        """The command u (m,) with its approach component replaced by a push, if needed.

        ``velocity`` (m,) the robot's, ``distance`` (m) and ``direction`` (unit, m) of the
        nearest detected obstacle; ``scale()`` (N) the force a new engagement starts from,
        asked only then. ``steady`` (m,): the steady push the robot is under (N, as the
        forces; the observer's estimate, where it stands out of the noise): in the zone the
        command also cancels its part toward the obstacle, which otherwise creeps the robot
        in below the speeds the rest of the rule answers (seen: a 1 m/s² field bump pressed a
        robot holding station 1 mm into an obstacle at 0.02 m/s).
        """
        u = np.asarray(u, dtype=float)
        n = np.asarray(direction, dtype=float)[:u.size]
        v = np.asarray(velocity, dtype=float)[:u.size]
        a = -float(v @ n)
        # the steady push toward the obstacle, N: the zone cancels it, the look-ahead counts it
        toward = max(0.0, -float(np.asarray(steady, dtype=float)[:u.size] @ n)) \
            if steady is not None else 0.0
        reach = self.reach(v, n)
        entry = self.entry_speed(a, distance, toward)
        if not distance < reach and self.sensing.step_gain > 0.0 and entry > 0.0:
            stop = self.stop_distance(entry, scale(), toward)
            if stop >= self.zone or self.force > 0.0:   # the zone alone cannot stop it
                reach = self.zone + max(self.lead * entry, stop)
        if not (distance < reach) or float(n @ n) < 0.5:
            self.release()                         # out of reach (or no direction)
            return u
        self.push, self.normal = 0.0, None
        inside = distance < self.zone
        want = -math.inf
        if inside:                                 # in the zone: no force toward it, nor push
            want = toward
        # an approach noise cannot have made is answered in full (with exact odometry, any)
        sense, rest = self.sensing, self.sensing.rest(0.0)
        lag, noise = sense.lag, sense.difference
        creeping = inside and self._creeping(a)
        if not inside:
            self._creep.clear()
            self._full = 0
        # moving away: by more than noise alone shows (with exact odometry, not approaching)
        if a < -noise / math.sqrt(2.0) if noise else a <= 0.0:
            if self.prev is not None:
                self.force *= 0.5                  # the approach reversed: it overshot
            self.prev = None
            self._recent.clear()
        elif a > 0.0:
            # s to contact at this speed (>= Δt); ahead of the zone, twice the time to reach
            # it: the speed falling at a constant rate just stops there
            contact = max(distance, self.dt * a) / a if inside else 2.0 * (distance - self.zone) / a
            self._recent.append(a)
            while len(self._recent) > lag + 1:
                self._recent.popleft()
            short = False
            if self._wait > 0:
                self._wait -= 1                    # the last change has not shown yet
            elif self.prev is not None and len(self._recent) > lag:
                short = slowing_too_little(a, self._recent[0], lag * self.dt, contact, rest,
                                           noise)
            if self.force <= 0.0:
                if inside or short:                # ahead of the zone: only once it must
                    self.force = min(max(scale(), 1.0), self.limit)
                    self._wait = lag - 1
            elif short:
                self.force = min(2.0 * self.force, self.limit)
                self._wait = lag - 1
            self.prev = a
            if self.force > 0.0:
                want = max(want, self.force * (min(1.0, a / rest) if rest > 0.0 else 1.0))
        if creeping:                               # an approach below the noise, shown over time
            self.force = min(2.0 * self.force, self.limit) if self.force > 0.0 else \
                min(max(scale(), 1.0), self.limit)
            self._full = self._creep_steps
            self._creep.clear()
        if self._full > 0:                         # (zero out of the zone)
            self._full -= 1
            want = max(want, self.force)
        along = float(u @ n)
        if along >= want:
            return u
        self.push, self.normal = want - along, n.copy()
        return np.asarray(u + self.push * n, dtype=float)

    def entry_speed(self, a: float, distance: float, toward: float = 0.0) -> float:
        """m/s: the speed an approach at a (m/s), ``distance`` (m) out, has at the zone's edge.

        Under a steady push ``toward`` the obstacle (N), through :attr:`Sensing.step_gain`; a where
        that is not known, or inside the zone; 0 moving away. An approach a push presses on
        is watched to the speed it will have: a keep-off that let go of a 110 kg rover
        slowed to 0.45 m/s 0.78 m out (beyond 0.3 m + 1 s at that speed) took it again in
        the zone, pressed back up to 0.8 m/s, and it crossed the boundary by 1 mm.
        """
        gap = distance - self.zone
        if a <= 0.0:
            return 0.0
        gain = self.sensing.step_gain
        if gain <= 0.0 or gap <= 0.0 or toward <= 0.0:
            return a
        return math.sqrt(a * a + 2.0 * toward * gain / self.dt * gap)

    def stop_distance(self, a: float, start: float, toward: float = 0.0) -> float:
        """m: the least way an approach at a (m/s) goes on under this rule's pushes.

        The push at its fastest: nothing for the actuation delay, then ``start`` (N) doubled
        every lag (:attr:`Sensing.lag`) up to ``limit``, less ``toward`` (N, a steady push
        toward the obstacle), each step taking its force times :attr:`Sensing.step_gain` off the
        approach speed. 0 where the input gain is not known; inf where the push cannot
        stop the approach within a minute.

        Where this reaches beyond the zone, the zone alone cannot stop the approach and the
        look-ahead acts however oblique it is: a 110 kg rover at 200 N, pushed by a 55 N
        sinusoid, ran at a boundary 47° off head-on at 0.93 m/s and crossed it by 0.018 m
        (it needs 0.30 m at the limit, 0.39 m with the ramp from the probing scale; the zone
        is 0.3 m). On the 40 kg rover at 1000 N the zone stops an approach up to 1.6 m/s.
        """
        gain = self.sensing.step_gain
        if gain <= 0.0 or a <= 0.0:
            return 0.0
        lag, dead = self.sensing.lag, self.sensing.dead_steps
        force, speed, way = min(max(start, 1.0), self.limit), a, a * dead * self.dt
        for k in range(int(round(60.0 / self.dt))):
            if k > 0 and k % lag == 0:
                force = min(2.0 * force, self.limit)
            fall = (force - toward) * gain
            if fall <= 0.0 and force >= self.limit:
                return math.inf
            step = min(speed, max(fall, 0.0))
            way += (speed - 0.5 * step) * self.dt
            speed -= step
            if speed <= 0.0:
                return way
        return math.inf

    def _creeping(self, a: float) -> bool:
        """Whether the robot creeps in below the speed noise can show (in the zone, each step).

        With odometry noise one approach speed a is answered only in proportion to what
        noise cannot have made (:meth:`Sensing.rest`), and a robot a push the observer does
        not call steady (a sinusoid) presses in at a few cm/s is answered by a fraction of
        the push (robot_side's noisy, delayed 0.1 Hz sinusoid, seed 3: 0.25 m to contact in
        3.4 s at 0.05-0.08 m/s under a push of 20-60 N, then 0.001 m deep). The mean of the
        approach speeds in the zone since it was entered or the last creep found, over at
        most ``lead`` (k steps, more than the actuation lag; the noise is independent per
        step, σ_v / √k on the mean) shows such a creep: it is called at the false-alarm rate, and then the
        push goes on in full, at twice the force, for the next ``lead``, and the speeds are
        judged afresh. With exact odometry every approach is answered in full already: no
        test.
        """
        sigma = self.sensing.velocity_std
        if sigma <= 0.0:
            return False
        self._creep.append(a)
        while len(self._creep) > self._creep_steps:
            self._creep.popleft()
        if len(self._creep) <= self.sensing.lag:
            return False                           # what the last change did has not shown yet
        bound = Z_FALSE_ALARM * sigma / math.sqrt(len(self._creep))
        return float(np.mean(self._creep)) > bound

    @property
    def _creep_steps(self) -> int:
        """Steps of the creep test's window and of the full push it starts (``lead``, > lag)."""
        return max(int(round(self.lead / self.dt)), self.sensing.lag + 1)

    def release(self) -> None:
        """Out of the zone: no push, and the next engagement starts afresh."""
        self.force, self.prev, self.push, self.normal = 0.0, None, 0.0, None
        self._recent.clear()
        self._creep.clear()
        self._wait = 0
        self._full = 0


def face_ahead(distance: float, normal: Array, velocity: Array) -> tuple[float, Array]:
    """The obstacle ahead along the velocity, as :class:`KeepOff` takes an obstacle.

    The safety node reports how far the robot's disc travels along its velocity v before
    it meets a detected obstacle (s, m) and the boundary's unit normal n there, toward
    the robot. The keep-off wants a distance and a direction: the distance of the robot
    from the boundary's line along n, s cos θ with cos θ = -v̂ · n, so that its time to
    contact at the approach speed a = -v · n = |v| cos θ is s / |v|, the time along the
    ray. The nearest obstacle need not be this one: a robot sliding along one face into
    another ahead is near the first until it touches the second (seen: 5 mm deep, a
    120 kg rover at 60 N of probing). A second :class:`KeepOff` acts on this one.
    """
    n = np.asarray(normal, dtype=float)
    v = np.asarray(velocity, dtype=float)[:n.size]
    speed = float(np.linalg.norm(v))
    if not math.isfinite(distance) or speed <= 0.0:
        return math.inf, n
    return distance * max(-float(v @ n) / speed, 0.0), n
