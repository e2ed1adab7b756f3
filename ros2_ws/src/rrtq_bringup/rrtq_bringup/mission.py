"""Mission bookkeeping from the robot's true odometry (no rclpy): when a run ends, and how it went.

The monitor judges the true state (/odom/truth) against the true obstacles and the bounds
of the scenario (:class:`rrtq_sim.referee.Referee`), not against what any node believes:
the collision check here is the referee's, not the safety node's. ``rrtq robot``, which has
no truth, judges /odom on the mission's time (:class:`MissionClock`).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Sequence

import numpy as np

from rrtq_common.settings import setting
from rrtq_common.world import TrueObstacles
from rrtq_controller.staleness import OdometryWatch
from rrtq_sim.referee import Bounds, Referee


class Outcome(enum.StrEnum):
    """How a run ended."""

    RUNNING = 'running'
    GOAL_REACHED = 'goal_reached'
    COLLISION = 'collision'
    OUT_OF_BOUNDS = 'out_of_bounds'
    DURATION = 'duration_elapsed'
    NODE_FAILED = 'node_failed'
    ODOMETRY_LOST = 'odometry_lost'
    """``rrtq robot``: the odometry stopped before the mission ended (the plant vanished)."""
    INTERRUPTED = 'interrupted'


@dataclasses.dataclass(frozen=True)
class MissionConfig:
    """What ends a run."""

    goal: tuple[float, float]      # m
    duration: float                # s of sim time
    robot_radius: float            # m
    bounds: Bounds                 # m; the robot's centre leaving them ends the run
    dt: float                      # s, plant step (for the effort integral)
    goal_tolerance: float = setting(0.5, unit='m', low=1e-3,
                                    doc='distance to the goal that counts as reached')
    stop_at_goal: bool = True      # plant-only runs drive a script: they run out the clock


def _percentiles(values: Sequence[float], qs: Sequence[float]) -> dict[str, float | None]:
    names = {50: 'median', 95: 'p95', 99: 'p99', 100: 'max'}
    if not values:
        return {names[q]: None for q in qs}
    arr = np.asarray(values, dtype=float)
    return {names[q]: float(np.percentile(arr, q)) for q in qs}


class MissionMonitor:
    """Feeds on the true odometry and the commands; says when the run is over and summarises it."""

    def __init__(self, config: MissionConfig, truth: TrueObstacles) -> None:
        self.config = config
        self.truth = truth
        self.referee = Referee(config.robot_radius, config.bounds)
        self.outcome = Outcome.RUNNING
        self.reason = ''
        self.t = 0.0
        self.steps = 0
        self.position: np.ndarray | None = None
        self.path_length = 0.0
        self.commands: dict[float, float] = {}
        self.min_clearance = math.inf
        self.time_to_goal: float | None = None
        self.collided = False
        self.contact_steps = 0
        self._pending_contact: tuple[float, tuple[str, ...]] | None = None
        self.controller_step_ms: list[float] = []
        self.replan_ms: list[float] = []
        self.replans = 0
        self.no_path_since: float | None = None

    def clearance(self, position: np.ndarray, t: float) -> float:
        """Advance the truth to ``t``; signed gap (m) of the robot's disc to the nearest obstacle.

        Negative when they overlap, also inside an obstacle at robot radius 0.
        """
        return self.referee.clearance(position, self.truth.update(position, t))[0]

    def on_odometry(self, t: float, position: np.ndarray) -> Outcome:
        """Account one sample of the true odometry; returns the (possibly new) outcome."""
        if self.outcome is not Outcome.RUNNING:
            return self.outcome
        if self.position is not None:
            self.path_length += float(np.linalg.norm(position - self.position))
        self.position = np.asarray(position, dtype=float).copy()
        self.t = t
        self.steps += 1
        judged = self.referee.judge(self.position, self.truth.update(self.position, t))
        clearance = judged.clearance
        self.min_clearance = min(self.min_clearance, clearance)
        goal_dist = float(np.linalg.norm(self.position - np.asarray(self.config.goal)))
        if clearance < 0.0:
            self.collided = True
            self.finish(Outcome.COLLISION, f'collision at t={t:.2f} s, position '
                        f'({position[0]:.2f}, {position[1]:.2f}), {-clearance:.3f} m deep')
        elif judged.out_of_bounds:
            (x0, x1), (y0, y1) = self.config.bounds
            self.finish(Outcome.OUT_OF_BOUNDS, f'out of bounds at t={t:.2f} s, position '
                        f'({position[0]:.2f}, {position[1]:.2f}), '
                        f'{-judged.bounds_clearance:.3f} m outside x [{x0:g}, {x1:g}], '
                        f'y [{y0:g}, {y1:g}]')
        elif goal_dist <= self.config.goal_tolerance and self.time_to_goal is None:
            self.time_to_goal = t
            if self.config.stop_at_goal:
                self.finish(Outcome.GOAL_REACHED, f'goal reached at t={t:.2f} s')
        elif t >= self.config.duration - 1e-9:
            reason = f'duration {self.config.duration:g} s elapsed'
            if self.no_path_since is not None:
                reason += (f'; the planner has had no path to the goal since '
                           f't={self.no_path_since:.2f} s (goal cut off)')
            self.finish(Outcome.DURATION, reason)
        if self._pending_contact is not None and self._pending_contact[0] <= t + 1e-9:
            self._physical_contact(*self._pending_contact)
        return self.outcome

    def on_contact(self, t: float, obstacles: tuple[str, ...], contact_steps: int) -> None:
        """The physics plant felt the robot touch ``obstacles`` in the step ending at ``t`` (s).

        A collision like the referee's overlap, which it usually accompanies (MuJoCo's soft
        contact lets the disc in by millimetres). The outcome is ``collision`` and the reason
        names the physical contact whichever of the step's contact and odometry arrives
        first: a contact ahead of its odometry waits for it.
        """
        self.contact_steps = max(self.contact_steps, int(contact_steps))
        if t > self.t + 1e-9 and self.outcome is Outcome.RUNNING:
            if self._pending_contact is None:
                self._pending_contact = (t, obstacles)
            return
        if self.outcome is Outcome.RUNNING or abs(self.t - t) <= 1e-9:
            self._physical_contact(t, obstacles)

    def _physical_contact(self, t: float, obstacles: tuple[str, ...]) -> None:
        self.collided = True
        self.outcome = Outcome.COLLISION
        self.reason = (f'physical contact with {", ".join(obstacles)} at t={t:.2f} s '
                       '(plant.model: mujoco)')

    def on_plan_status(self, t: float, has_path: bool) -> None:
        """Track since when the planner has had no path (for the failure reason)."""
        if has_path:
            self.no_path_since = None
        elif self.no_path_since is None:
            self.no_path_since = t

    def on_command(self, t: float, u: np.ndarray) -> None:
        """Record the command of the step at ``t`` (a repeat of a step replaces it)."""
        self.commands[round(t, 9)] = float(np.dot(u, u))

    def commands_complete(self) -> bool:
        """True when a command is held for every step before the last (or none at all)."""
        if not self.commands:
            return True
        applied = sum(1 for t in self.commands if t < self.t - 1e-9)
        return applied >= self.steps - 1

    @property
    def control_effort(self) -> float:
        """Sum of |u|^2 dt (N^2 s) over the commands applied: those before the last step."""
        return sum(v for t, v in self.commands.items() if t < self.t - 1e-9) * self.config.dt

    def finish(self, outcome: Outcome, reason: str) -> None:
        if self.outcome is Outcome.RUNNING:
            self.outcome, self.reason = outcome, reason

    @property
    def success(self) -> bool:
        """Reached the goal without touching an obstacle."""
        return self.time_to_goal is not None and not self.collided and self.outcome in (
            Outcome.GOAL_REACHED, Outcome.DURATION)

    def summary(self) -> dict:
        """The fields of summary.json that odometry and commands determine."""
        return {
            'success': self.success,
            'collided': self.collided,
            'contact_steps': self.contact_steps,
            'outcome': str(self.outcome),
            'reason': self.reason,
            'time_to_goal_s': self.time_to_goal,
            'sim_time_s': round(self.t, 9),
            'steps': self.steps,
            'path_length_m': self.path_length,
            'control_effort': self.control_effort,
            'commands': len(self.commands),
            'min_clearance_m': None if math.isinf(self.min_clearance) else self.min_clearance,
            'replans': self.replans,
            'no_path_since_s': self.no_path_since,
            'replan_ms': _percentiles(self.replan_ms, (50, 95, 100)),
            'controller_step_ms': _percentiles(self.controller_step_ms, (50, 95)),
        }


class MissionClock:
    """The mission's time of the odometry, and the odometry's age (no rclpy).

    On sim time the mission's time is the stamp; on wall time, the wall time since the first
    odometry (its stamps are the plant's wall clock).
    """

    def __init__(self, odometry_timeout_s: float) -> None:
        self.watch = OdometryWatch(odometry_timeout_s, 1.0)
        self.sim_time = False
        self.t0: float | None = None

    def odometry(self, stamp: float, wall: float) -> float:
        """Note odometry stamped ``stamp`` (s) at wall time ``wall`` (s); its mission time."""
        self.watch.arrived(stamp, wall)
        if self.t0 is None:
            self.t0 = 0.0 if self.sim_time else stamp
        return self.time_of(stamp)

    def time_of(self, stamp: float) -> float:
        """The mission's time of a stamp (s)."""
        return stamp - (self.t0 or 0.0)
