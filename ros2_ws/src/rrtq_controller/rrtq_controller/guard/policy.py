"""The guard's decisions on the policy: events, the trust region, coverage, divergence.

The controller adopts a new actor target only when it passes stated checks
(:meth:`rrtq_controller.policy_iteration.PolicyIteration.policy_improvement`), bounds
each change (:func:`trust_step`) to where the data are (:func:`held_below`), and watches
every leg for divergence (:class:`DivergenceWatch`), reverting to the last policy that
completed a leg. :data:`FALSE_ALARM` is the rate of every rule of the guard that reads
noisy measurements (here and in :mod:`.forces`).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm

from rrtq_common.geometry import kinodynamic_distance, ray_distance, segment_distance

Array = NDArray[np.float64]

FALSE_ALARM = 0.01
"""α: the rate at which a rule of the guard calls an effect that measurement noise alone made
(a force too weak, a reversal, a robot not at rest)."""


class PolicyEvent(enum.Enum):
    """What the guard decided about the actors' policy (``ControllerState.policy_event``)."""

    ADOPTED = 'adopted'
    """A new actor target passed every check (possibly shortened by the trust region)."""
    REJECTED = 'rejected'
    """The critic's proposal failed a check; the actors keep their current target."""
    REVERTED = 'reverted'
    """A leg diverged: the actors are back at the last policy that completed a leg."""
    HOLD = 'hold'
    """A leg diverged before any policy completed a leg: the safe hold (:class:`.forces.Brake`)."""
    HELD_SHORT = 'held_short'
    """A leg ran its horizon short of its waypoint: the retry adds integral action
    (:class:`rrtq_controller.held_short.HeldShort`)."""


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
    brakes, :class:`.forces.Brake`, until the margin and the plan have caught up with the robot). Every
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

