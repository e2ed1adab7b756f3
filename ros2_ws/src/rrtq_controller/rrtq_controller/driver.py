"""What the controller node runs each step: plan -> legs -> force (no rclpy).

A :class:`Driver` is one controller variant behind the node: it adopts a plan when its
stamp changes, refuses non-finite odometry (zero force, nothing learned from it), and
keeps the paced-mode watchdog that stops pushing when the odometry goes stale.
``LearningDriver`` walks the planner's waypoints leg by leg (RRT-QX Algorithm 1) with
the Q-learning controller; ``OpenLoopDriver`` plays a scripted force profile; the vf_lpc
variant's is :class:`rrtq_controller.vf_lpc.driver.VFLPCDriver`.
:func:`rrtq_controller.drivers.make_driver` picks the driver of a :class:`Variant`.
"""

from __future__ import annotations

import abc
import dataclasses
import enum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rrtq_common.lockstep import OnChange

from .config import ControllerConfig
from .legs import LegEvent, LegSequencer
from .open_loop import ForceProfile
from .q_learning import QLearningController

Array = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class ControlOutput:
    """One step's command and the state worth publishing about it."""

    u: Array                          # N, force to hold over the next step
    leg_index: int
    leg_start_time: float             # s
    leg_start: Array                  # (2,) m
    leg_target: Array                 # (2,) m
    d0: float                         # m (RRT-QX (4))
    d: float                          # m (RRT-QX (5))
    time_to_go: float                 # s
    probing: Array                    # N
    critic_weights: Array
    actor_weights: Array
    disturbance_weights: Array
    critic_error: float
    terminal_error: float
    event: str                        # LegEvent value, or 'no_plan'
    time_rates: tuple[float, ...] = ()   # the critic's time basis (learning variants)
    time_powers: tuple[int, ...] = ()
    policy_event: str = ''               # the guard's events this step (guard.PolicyEvent)
    policy_reason: str = ''
    tracking_error: float = 0.0          # vf_lpc: m, robot to the reference's first sample
    prediction_error: Array = dataclasses.field(default_factory=lambda: np.zeros(0))
    nominal_error: Array = dataclasses.field(default_factory=lambda: np.zeros(0))
    prediction_std: Array = dataclasses.field(default_factory=lambda: np.zeros(0))
    gp_dictionary: int = 0
    horizon_cost: float = 0.0
    keep_off: float = 0.0                # N: the pushes away from the nearest and ahead obstacles


class Watch(enum.Enum):
    """What the odometry watchdog found (paced mode)."""

    FRESH = 'fresh'
    """Odometry is arriving (or no step was answered yet): nothing to do."""
    WENT_STALE = 'went_stale'
    """No odometry for longer than the timeout, for the first time: command zero."""
    STALE = 'stale'
    """Still no odometry: keep commanding zero."""


class Driver(abc.ABC):
    """A controller variant as the node drives it, step by step.

    Parameters
    ----------
    config : ControllerConfig
    n, m, q : int
        State, input and disturbance dimensions.
    rng : numpy.random.Generator
        Source of the probing noise.
    """

    def __init__(self, config: ControllerConfig, n: int, m: int, q: int,
                 rng: np.random.Generator) -> None:
        self.config = config
        self.n, self.m, self.q = n, m, q
        self._plan_stamp = -1
        self._last_odometry: float | None = None
        self._answered = False
        self.stale = False
        self.nearest: tuple[float, Array] | None = None
        """The nearest detected obstacle at this step (see :meth:`control`)."""
        self.ahead: tuple[float, Array] | None = None
        """The detected obstacle ahead along the velocity at this step (see :meth:`control`)."""

    @property
    def warnings(self) -> list[str]:
        """What the node should warn about at start (gains against the stability bounds)."""
        return []

    def set_guidance(self, reference: OnChange[tuple[Array, int]] | None,  # noqa: B027
                     obstacles: OnChange[list[Array]] | None) -> None:
        """Take the guidance reference (K, n) and its rollout count, and the obstacles.

        vf_lpc only (the augmented obstacles carry its barrier); the others ignore them.
        """

    def set_odometry_variance(self, variance: ArrayLike) -> None:  # noqa: B027
        """Take the variance of each state's measurement (the odometry's covariance diagonal).

        The learning variants allow for it (``QLearningController.set_odometry_variance``).
        """

    @abc.abstractmethod
    def set_plan(self, waypoints: ArrayLike, x: ArrayLike, t: float) -> None:
        """Adopt the planner's waypoints (the robot's next waypoint first, the goal last)."""

    @abc.abstractmethod
    def step(self, t: float, x: ArrayLike, d_applied: ArrayLike | None = None) -> ControlOutput:
        """The force for the step at ``t`` (s) from the full measured state ``x``."""

    def control(self, t: float, x: ArrayLike, plan: OnChange[Array] | None,
                disturbance: ArrayLike | None,
                reference: OnChange[tuple[Array, int]] | None = None,
                obstacles: OnChange[list[Array]] | None = None,
                nearest: tuple[float, Array] | None = None,
                ahead: tuple[float, Array] | None = None) -> ControlOutput | None:
        """One step: adopt a plan that changed (and the guidance), then :meth:`step`.

        ``nearest``: the nearest detected obstacle (distance m, unit vector from it to the
        robot) as the safety node reports it, for the learning variants' keep-off, and
        ``ahead`` the one ahead along the velocity (distance the disc travels to it, m, and
        the unit normal there toward the robot), for their second keep-off.
        None for non-finite odometry: the node commands zero, and nothing is learned.
        A non-finite disturbance measurement is not used.
        """
        self._answered = True
        state = np.asarray(x, dtype=float)
        if not np.all(np.isfinite(state)):
            return None
        if plan is not None and plan.stamp_ns != self._plan_stamp:
            self._plan_stamp = plan.stamp_ns
            self.set_plan(plan.read(), state, t)
        self.set_guidance(reference, obstacles)
        self.nearest, self.ahead = nearest, ahead
        d = None
        if disturbance is not None and np.all(np.isfinite(disturbance)):
            d = np.asarray(disturbance, dtype=float)
        return self.step(t, state, d)

    def odometry_arrived(self, wall: float) -> bool:
        """Note odometry at wall time ``wall`` (s); True when it ends a stale spell."""
        self._last_odometry = wall
        resumed, self.stale = self.stale, False
        return resumed

    def watch(self, wall: float) -> Watch:
        """Paced mode: stop pushing when the odometry has gone stale.

        Like Nav2's collision monitor on a timed-out source: the state the command was
        for is unknown.
        """
        if self._last_odometry is None or not self._answered:
            return Watch.FRESH
        if wall - self._last_odometry <= self.config.stale_timeout_s:
            return Watch.FRESH
        if self.stale:
            return Watch.STALE
        self.stale = True
        return Watch.WENT_STALE


class LearningDriver(Driver):
    """Leg sequencing (RRT-QX (4)-(5)) around the Q-learning controller."""

    def __init__(self, config: ControllerConfig, n: int, m: int, q: int,
                 rng: np.random.Generator) -> None:
        super().__init__(config, n, m, q, rng)
        self.controller = QLearningController(config, n, m, q, rng)
        self.legs = LegSequencer(config.rho, config.horizon, n)

    @property
    def warnings(self) -> list[str]:
        """The configured gains that violate a stability bound."""
        return self.controller.warnings

    def set_odometry_variance(self, variance: ArrayLike) -> None:
        """See :meth:`QLearningController.set_odometry_variance`."""
        self.controller.set_odometry_variance(np.asarray(variance, dtype=float))

    def set_plan(self, waypoints: ArrayLike, x: ArrayLike, t: float) -> None:
        """Adopt the planner's waypoints (the robot's next waypoint first, the goal last).

        The current leg goes on when the new plan still passes through its target (the
        planner improved or repaired what lies beyond it); otherwise a new leg starts
        from the current state toward the plan's first waypoint.
        """
        x = np.asarray(x, dtype=float)
        points = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        if not len(points):
            # No path to the goal: hold where the robot is (a leg to its own position)
            # until the planner finds one again.
            if self.legs.leg is not None and np.allclose(self.legs.leg.target[:2], x[:2]):
                return
            points = x[None, :2].copy()
        before = None if self.legs.leg is None else self.legs.leg.target.copy()
        if self.legs.follow_plan(points, x, t):
            assert self.legs.leg is not None
            self.controller.start_leg(self.legs.x_bar(x), t, completed=False,
                                      moved=self._moved(before))

    def step(self, t: float, x: ArrayLike, d_applied: ArrayLike | None = None) -> ControlOutput:
        x = np.asarray(x, dtype=float)
        before = None if self.legs.leg is None else self.legs.leg.target.copy()
        event = self.legs.update(x, t)
        c = self.controller
        if event is LegEvent.NO_PLAN:
            return self._output(np.zeros(self.m), x, event.value, t)
        if event is LegEvent.NEW_LEG:
            c.start_leg(self.legs.x_bar(x), t, completed=self.legs.completed,
                        moved=self._moved(before))
        elif event is LegEvent.RENEWED:
            c.renew_horizon(self.legs.x_bar(x), t)
        elif event is LegEvent.GOAL_REACHED and self.legs.completed:
            c.completed_leg()
        u = c.step(t, self.legs.x_bar(x),
                   None if d_applied is None else np.asarray(d_applied, dtype=float),
                   self.nearest, self.ahead)
        return self._output(u, x, event.value, t)

    def _moved(self, before: Array | None) -> Array | None:
        """How far the leg's target moved from ``before`` (None: there was no leg)."""
        assert self.legs.leg is not None
        return None if before is None else self.legs.leg.target - before

    def _output(self, u: Array, x: Array, event: str, t: float) -> ControlOutput:
        leg, c = self.legs.leg, self.controller
        empty = np.zeros(0)
        return ControlOutput(
            u=u, leg_index=leg.index if leg else 0,
            leg_start_time=leg.start_time if leg else 0.0,
            leg_start=leg.x0[:2].copy() if leg else x[:2].copy(),
            leg_target=leg.target[:2].copy() if leg else x[:2].copy(),
            d0=leg.d0 if leg else 0.0, d=self.legs.distance(x) if leg else 0.0,
            time_to_go=c.time_to_go(t) if leg else 0.0,
            probing=np.asarray(c.info.probing if c.info.probing.size else np.zeros(self.m)),
            critic_weights=c.critic_weights, actor_weights=c.actor_weights,
            disturbance_weights=c.disturbance_weights if c.robust else empty,
            critic_error=float(c.info.e_c1), terminal_error=float(c.info.e_c2), event=event,
            time_rates=tuple(c.time_basis.rates), time_powers=tuple(c.time_basis.powers),
            policy_event=c.info.policy_event, policy_reason=c.info.policy_reason,
            keep_off=c.info.keep_off)


class OpenLoopDriver(Driver):
    """The scripted force profile; the 'leg' is the whole run toward the goal."""

    def __init__(self, config: ControllerConfig, n: int, m: int, q: int,
                 rng: np.random.Generator) -> None:
        super().__init__(config, n, m, q, rng)
        self.profile = ForceProfile.from_rows(config.forces)
        self.goal = np.asarray(config.goal, dtype=float)
        self.x0: Array | None = None

    def set_plan(self, waypoints: ArrayLike, x: ArrayLike, t: float) -> None:
        """A scripted run ignores plans."""

    def step(self, t: float, x: ArrayLike, d_applied: ArrayLike | None = None) -> ControlOutput:
        x = np.asarray(x, dtype=float)
        target = np.concatenate([self.goal, np.zeros(x.size - 2)])
        if self.x0 is None:
            self.x0 = x.copy()
        u = self.profile.force_at(t)
        empty = np.zeros(0)
        return ControlOutput(
            u=u, leg_index=0, leg_start_time=0.0, leg_start=self.x0[:2].copy(),
            leg_target=self.goal.copy(), d0=float(np.linalg.norm(self.x0 - target)),
            d=float(np.linalg.norm(x - target)), time_to_go=max(0.0, self.config.horizon - t),
            probing=np.zeros(u.size), critic_weights=empty, actor_weights=empty,
            disturbance_weights=empty, critic_error=0.0, terminal_error=0.0,
            event=LegEvent.CONTINUE.value)

