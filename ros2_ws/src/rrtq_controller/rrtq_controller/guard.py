"""Guards of safe learning (beyond the papers): trust region, divergence watch, events.

The papers' actor follows the critic's greedy policy at every step. Where the critic was
fitted to little data (the first legs from a zero gain, one direction of motion), its
cross terms Q̂_ux are poorly identified and the greedy gain can be arbitrarily large: on
the rover without a spring the first greedy policy once commanded -3.2e5 N. The
controller therefore adopts a new actor target only when it passes stated checks
(:meth:`rrtq_controller.q_learning.QLearningController.policy_improvement`), bounds
each change (:func:`trust_step`), and watches every leg for divergence
(:class:`DivergenceWatch`), reverting to the last policy that completed a leg.
Everything here is model-free: it uses the data, the cost weights and the actuator's
limit, never the plant's matrices.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm

from rrtq_common.geometry import kinodynamic_distance, ray_distance, segment_distance

Array = NDArray[np.float64]


class PolicyEvent(enum.Enum):
    """What the guard decided about the actors' policy (``ControllerState.policy_event``)."""

    ADOPTED = 'adopted'
    """A new actor target passed every check (possibly shortened by the trust region)."""
    REJECTED = 'rejected'
    """The critic's proposal failed a check; the actors keep their current target."""
    REVERTED = 'reverted'
    """A leg diverged: the actors are back at the last policy that completed a leg."""
    HOLD = 'hold'
    """A leg diverged before any policy completed a leg: the safe hold (:class:`Brake`)."""


def trust_step(change: Array, current: Array, floor: float, growth: float) -> float:
    """Length s in (0, 1] of the step from the actors' target toward the critic's proposal.

    ``change`` and ``current`` are norms of the proposed change and of the current
    target (‖K̂*(τ) - K̂(τ)‖ and ‖K̂(τ)‖ on a grid of τ): the trust region allows a
    change of at most ``growth`` times the current size, or ``floor`` where that is
    smaller (so that a zero gain can start). A policy may become twice as aggressive
    per adoption, not a hundred times.

    Returns
    -------
    float
        1 when the whole step fits, else the largest fraction of it that does.
    """
    radius = growth * np.maximum(current, floor)
    over = change > radius
    return float(np.min(radius[over] / change[over])) if over.any() else 1.0


def held_below(batch: Callable[[Array], Array], W: Array, tau_low: float, horizon: float,
               points: int = 41) -> Array:
    """Weights whose gain is W's for τ >= ``tau_low`` and held at its value there below.

    A critic identifies the Q-function only at the times-to-go its samples cover; below
    them its greedy gain is an extrapolation of the time basis, and on the rover without
    a spring it once pushed the robot away near the end of a long leg (K̂(1 s) = -81 N/m
    against the optimum's +4.6). The proposal is therefore re-expressed, in the same time
    basis ``batch`` (τ -> φ(τ), (N,) -> (N, L)), as the least-squares fit on a grid of
    [0, horizon] to the gain W gives at max(τ, ``tau_low``): the gain of a longer horizon
    where the data say nothing, as a receding-horizon controller would use. The gain is
    linear in W, so this is one small least-squares problem on the weights
    (L x (n m)). The refit is not exact where the samples do cover, so it is made only
    when the uncovered part is worth it: ``tau_low`` above 5 % of the horizon (the last
    half second of a 10 s leg); below, W is returned unchanged.
    """
    if tau_low <= 0.05 * horizon:
        return W
    taus = np.linspace(0.0, horizon, points)
    phi = batch(taus)
    coef = W.reshape(phi.shape[1], -1)
    held = batch(np.maximum(taus, tau_low)) @ coef
    fit = np.linalg.lstsq(phi, held, rcond=None)[0]
    return np.asarray(fit.reshape(W.shape), dtype=float)


@dataclass
class DivergenceWatch:
    """Declares a leg diverged when the robot runs away from its target.

    A leg diverges when D = ‖x̄‖ > ``distance`` D0 + ``floor`` (the robot is much farther
    from its target than the reference start), or when the speed ‖x̄[2:]‖ exceeds
    ``speed`` (L + ‖v0‖ T) / T + ``floor`` with L = ‖x̄0[:2]‖ the reference leg's length
    and v0 = x̄0[2:] its initial velocity: a multiple of the speed that covers the leg,
    and the motion it started with, in one horizon T. The reference (D0, L, v0) is the
    start of the last leg that began afresh (the first, one after a completed leg or
    after a revert): legs that a new plan or the horizon restarts keep it, so a robot
    that runs away cannot escape the watch by the legs it starts on its way. Such a leg
    has a new target, though, and its x̄ says how far the robot is from that one: when the
    caller says how far the target moved, D is measured from the reference leg's own
    target (x̄ + ``offset``, ``offset`` the sum of the moves), so a plan that sends the
    robot to a farther waypoint is not taken for a robot running away.

    A leg also diverges when the robot leaves its line: its distance from the ray from the
    leg's start through its target (:func:`rrtq_common.geometry.ray_distance`) exceeds
    the largest distance from its line of the legs before it (``widest`` at the leg's
    start: D_rob, RRT-QX eq. 6, as the safety node measures it, |x̄0 × x̄| / |x̄0|; its
    running maximum is the paper's margin, eq. 7, that the obstacles of the current plan
    were grown by) plus ``deviation`` (m). The plan keeps the segment grown by that margin
    clear; beyond it the plan no longer keeps the robot off the obstacles, whatever the
    policy. The ray, not the line: a robot drifting backwards past its start, away from
    its target, leaves that region with D_rob unchanged (seen on the rover without a
    spring: 1.1 m behind the start of a 0.59 m leg, into an obstacle). Past the target it
    is D_rob: an overshoot there is a learning policy's transient (1 m on the third leg of
    the robust learning test, which braking there made learn worse), and the leg is then
    near its end. :attr:`off_line` says that this criterion tripped (the controller then
    brakes, :class:`Brake`, until the margin and the plan have caught up with the robot). Every
    leg is measured from its own start, restarted or not. A leg no longer than
    ``deviation`` (holding station, or a robot told to stop where it is while moving) has
    no line at that scale: it is its segment, and the robot trips the watch farther than
    ``widest`` + ``deviation`` from it, plus the way its speed at the leg's start covers in
    ``stop_time`` (the brake's stopping time: a policy that stops the robot no shorter than
    the brake would is not holding it). Seen on an 80 kg rover from the defaults: the goal
    cut off, the hold leg's target 0.05 m away, an unstable policy drove the robot 2.3 m
    from it before D tripped (at 2 D0 + 1 of the reference leg), and the margin grew by as
    much.
    It trips at most once per leg (the controller starts it afresh where a brake has
    stopped the robot).
    """

    distance: float
    floor: float
    speed: float
    horizon: float
    d0: float = 0.0
    speed_bound: float = math.inf
    tripped: bool = False
    offset: Array | None = None
    """The reference leg's target seen from the current one's (state units), or None."""
    deviation: float = math.inf
    """m beyond ``widest`` (at the leg's start) at which a robot off its ray trips the watch."""
    widest: float = 0.0
    """m: the largest distance from its leg's line the robot has had so far (all legs)."""
    off_line: bool = False
    """Whether the last trip was the robot leaving its line (not D or the speed)."""
    line: Array | None = None
    """The current leg's start seen from its target, x̄0[:2] (None before the first leg)."""
    line_limit: float = math.inf
    stop_time: float = 0.0
    """s: a short leg allows the way its initial speed covers in this time (see above)."""
    short: bool = False
    """Whether the current leg is no longer than ``deviation`` (watched as its segment)."""
    leg_d0: float = math.inf
    """The current leg's own D0 (the reference's is :attr:`d0`)."""
    position_std: float = 0.0
    """σ_p, m per axis of the odometry: the line's limit allows z σ_p more, z the two-sided
    normal quantile of :data:`FALSE_ALARM` spread over a horizon's steps (a robot exactly on
    its line that noise alone trips on at most a share α of its legs)."""
    steps: int = 200
    """Steps of a horizon (T / Δt), over which :attr:`position_std`'s false alarm is spread."""

    def start(self, x0: Array, renew: bool = True, moved: Array | None = None) -> None:
        """A new leg from x̄0; ``renew`` makes it the reference.

        ``moved``: how far the target moved from the previous leg's (state units; None
        when the caller does not know, then D is the distance to the current target). A
        reference leg that started on its target (D0 = 0: the robot at rest before the
        first plan) is no reference; the next leg replaces it in any case. A leg that ends
        with the robot nearer its own target than it started (‖x̄0 + moved‖ < its D0) made
        progress, and the new leg becomes the reference too: a robot that follows a plan
        whose waypoints a new plan keeps replacing before it reaches them is not running
        away, though it gets ever farther from the old reference's target (seen on a
        120 kg rover: D = 7.5 m from a target three replans back, 2 D0 + 1 = 7.45, on a
        leg whose own D had fallen from 4.4 to 1.7 m; the hold threw away the policy).
        """
        x0 = np.asarray(x0, dtype=float)
        if not renew and moved is not None and self.line is not None:
            renew = float(np.linalg.norm(x0 + np.asarray(moved, dtype=float))) < self.leg_d0
        self.tripped = self.off_line = False
        self.line = x0[:2].copy()
        self.leg_d0 = float(np.linalg.norm(x0))
        self.short = float(np.linalg.norm(self.line)) <= self.deviation   # no line at that scale
        coast = float(np.linalg.norm(x0[2:])) * self.stop_time if self.short else 0.0
        # |distance| from the line: two-sided, α spread over the steps of a leg (union bound)
        noise = float(norm.ppf(1.0 - FALSE_ALARM / (2 * max(self.steps, 1)))) * self.position_std
        self.line_limit = self.widest + self.deviation + coast + noise
        if not renew and self.d0 > 1e-9:
            if moved is None or self.offset is None:
                self.offset = None
            else:
                self.offset = self.offset + np.asarray(moved, dtype=float)
            return
        self.offset = np.zeros_like(np.asarray(x0, dtype=float))
        self.d0 = float(np.linalg.norm(x0))
        length = float(np.linalg.norm(x0[:2]))
        v0 = float(np.linalg.norm(x0[2:]))
        self.speed_bound = self.speed * (length + v0 * self.horizon) / self.horizon + self.floor

    def check(self, x: Array) -> str:
        """'' while the leg is fine; the criterion it broke, the first time it breaks one."""
        off = self.distance_from_line(x)
        self.widest = max(self.widest, off)
        if self.tripped:
            return ''
        d = float(np.linalg.norm(x if self.offset is None else x + self.offset))
        bound = self.distance * self.d0 + self.floor
        if d > bound:
            self.tripped = True
            return f'D = {d:.3g} > {self.distance:g} D0 + {self.floor:g} = {bound:.3g}'
        v = float(np.linalg.norm(x[2:]))
        if v > self.speed_bound:
            self.tripped = True
            return f'speed {v:.3g} > {self.speed_bound:.3g} (bound from the leg length and T)'
        off = self.distance_from_segment(x) if self.short else self.distance_from_ray(x)
        if off > self.line_limit:
            self.tripped = self.off_line = True
            if self.short:
                return (f'{off:.3g} m from its short leg > {self.line_limit:.3g} m (the widest '
                        f'before + {self.deviation:g} + its initial speed for {self.stop_time:g} s)')
            return (f'{off:.3g} m off its line (ray) > {self.line_limit - self.deviation:.3g} m '
                    f'(the widest before) + {self.deviation:g}')
        return ''

    def distance_from_line(self, x: Array) -> float:
        """m: D_rob of x̄ on the current leg (its start x̄0, its target the origin of x̄)."""
        return 0.0 if self.line is None else kinodynamic_distance(self.line, (0.0, 0.0), x)

    def distance_from_segment(self, x: Array) -> float:
        """m: x̄'s distance from the current leg's segment (from x̄0 to the origin of x̄)."""
        return 0.0 if self.line is None else segment_distance(self.line, (0.0, 0.0), x)

    def distance_from_ray(self, x: Array) -> float:
        """m: x̄'s distance from the current leg's ray (from x̄0 through the origin of x̄)."""
        return 0.0 if self.line is None else ray_distance(self.line, (0.0, 0.0), x)


FALSE_ALARM = 0.01
"""α: the rate at which a rule of the guard calls an effect that measurement noise alone made
(a force too weak, a reversal, a robot not at rest)."""


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
        return float(norm.ppf(1.0 - FALSE_ALARM)) * math.sqrt(2.0) * self.velocity_std

    def rest(self, floor: float) -> float:
        """m/s: the speed below which a robot counts as at rest (a speed noise can make).

        ``floor`` with exact odometry; with noise, at least the speed a robot at rest shows
        with probability :data:`FALSE_ALARM` (|n| of a 2-D normal is Rayleigh:
        P(|n| > r) = exp(-r² / 2σ_v²)).
        """
        return max(floor, self.velocity_std * math.sqrt(2.0 * math.log(1.0 / FALSE_ALARM)))

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
    * when the velocity reversed (v · v_prev < 0: the step overshot rest), F halves.

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
            if float(v @ then) < 0.0 and min(speed, before) > noise / math.sqrt(2.0):
                self.force *= 0.5
                self._wait = lag - 1
            elif slowing_too_little(speed, before, lag * self.dt, self.stop_time, rest, noise):
                self.force = min(2.0 * self.force, self.limit)
                self._wait = lag - 1
        self.prev = v.copy()
        self.at_rest = speed <= rest
        return np.asarray(-self.force * v / max(speed, rest), dtype=float)


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
      a robot creeping in at 0.02 m/s under a steady push once touched an obstacle);
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
    sensing: Sensing = field(default_factory=Sensing)
    """Odometry noise and actuation delay the rules allow for (:class:`Sensing`)."""
    _recent: deque[float] = field(default_factory=deque)
    _wait: int = 0

    head_on: float = math.cos(math.pi / 4.0)
    """The look-ahead is for approaches within 45° of head-on (a >= this |v|)."""

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
        if not (distance < self.reach(v, n)) or float(n @ n) < 0.5:
            self.release()                         # out of reach (or no direction)
            return u
        self.push = 0.0
        a = -float(v @ n)
        inside = distance < self.zone
        want = -math.inf
        if inside:                                 # in the zone: no force toward it, nor push
            want = max(0.0, -float(np.asarray(steady, dtype=float)[:u.size] @ n)
                       if steady is not None else 0.0)
        # an approach noise cannot have made is answered in full (with exact odometry, any)
        sense, rest = self.sensing, self.sensing.rest(0.0)
        lag, noise = sense.lag, sense.difference
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
        along = float(u @ n)
        if along >= want:
            return u
        self.push = want - along
        return np.asarray(u + self.push * n, dtype=float)

    def release(self) -> None:
        """Out of the zone: no push, and the next engagement starts afresh."""
        self.force, self.prev, self.push = 0.0, None, 0.0
        self._recent.clear()
        self._wait = 0


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
