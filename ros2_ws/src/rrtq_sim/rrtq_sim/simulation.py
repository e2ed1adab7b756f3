"""The simulated robot: the plant's state, stepped with the held force and disturbance.

What the simulator node runs (no rclpy): the inputs it holds over a step, the spring
anchor, the actuator's delay (:class:`DelayLine`), and the rule that nothing non-finite or
misshapen ever reaches the plant.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.lockstep import seconds_to_ns
from rrtq_common.settings import check, setting
from rrtq_common.world import TrueObstacles
from rrtq_sim.mujoco_plant import MujocoPlant
from rrtq_sim.plant import Plant, SpringAnchor

__all__ = ['SimulatorConfig', 'Simulation', 'DelayLine', 'delay_steps']


@dataclass(frozen=True, kw_only=True)
class SimulatorConfig:
    """The simulator node's settings (the plant's are :class:`rrtq_sim.plant.PlantConfig`)."""

    start: tuple[float, float] = setting((0.0, 0.0), unit='m',
                                         doc='initial position; the robot starts at rest')
    speed: float = setting(0.0, low=0.0, doc='0: lock-step as fast as possible; > 0: '
                           'wall-clock pace factor')
    duration: float = setting(0.0, unit='s', low=0.0,
                              doc='stop stepping at this sim time (0: never)')
    acks: tuple[str, ...] = setting(('cmd_force',), doc='stamped outputs awaited before each '
                                    'lock-step step: cmd_force controller_state disturbance '
                                    'perception_status')
    wait_for: tuple[str, ...] = setting((), doc='topic:count pairs; the first step waits '
                                        'until each topic has that many subscribers')
    ready_from: tuple[str, ...] = setting((), doc='nodes whose writers must announce on '
                                          '/graph/ready that they reached their readers '
                                          'before the first step (rrtq_common.readiness)')
    settle_s: float = setting(0.5, unit='s', low=0.0, doc='wall time to wait once the graph '
                              'is connected, so that discovery between the other nodes '
                              'completes too')
    resend_period_s: float = setting(2.0, unit='s', low=0.01, doc='lock-step: republish the '
                                     'current odometry if acknowledgements stall this long '
                                     '(wall)')

    def __post_init__(self) -> None:
        check(self)


def delay_steps(delay: float, dt: float) -> int:
    """The actuation delay ``delay`` (s) in steps of ``dt`` (s).

    Raises
    ------
    ValueError
        When ``delay`` is negative, not finite or not a whole multiple of ``dt``.
    """
    if not (np.isfinite(delay) and delay >= 0.0):
        raise ValueError(f'must be finite and >= 0, got {delay}')
    steps = delay / dt
    whole = round(steps)
    if abs(steps - whole) > 1e-9 * max(1.0, steps):
        raise ValueError(f'must be a whole multiple of the step dt = {dt:g} s, got {delay:g} s '
                         f'({steps:.4g} steps)')
    return int(whole)


class DelayLine:
    """The actuator's delay: a first-in, first-out line of ``steps`` forces.

    What is pushed at step k comes out at step k + ``steps``; zeros come out before (no
    force before the first command).

    Parameters
    ----------
    steps : int
        The delay in steps (>= 0; 0: a force comes out at the step it is pushed).
    m : int
        Force dimension.
    """

    def __init__(self, steps: int, m: int) -> None:
        if steps < 0:
            raise ValueError(f'steps must be >= 0, got {steps}')
        self.steps = int(steps)
        self._line: deque[np.ndarray] = deque(np.zeros(m) for _ in range(self.steps))

    def shift(self, u: np.ndarray) -> np.ndarray:
        """Push the force commanded at this step; return the one that acts over it."""
        if not self.steps:
            return u
        self._line.append(np.array(u, dtype=float))
        return self._line.popleft()


class Simulation:
    """The full state x (world frame) of ``plant``, one exact zero-order-hold step at a time.

    Parameters
    ----------
    plant : Plant or MujocoPlant
    start : array_like, shape (2,)
        Initial position, m (at rest).
    anchor : SpringAnchor
        ``leg_target``: the spring follows the controller's target; else the origin.
    duration : float
        Sim time after which no step is taken, s (0: never).
    delay : int
        The actuator's delay in steps: the force held at step k acts over step k + delay
        (the spring's anchor is not delayed).
    truth : TrueObstacles, optional
        The physics plant's obstacles as they come and go: before each step the plant's
        geoms are switched to what exists (the spawner's referee keeps the same truth).
    """

    def __init__(self, plant: Plant | MujocoPlant, start: npt.ArrayLike, anchor: SpringAnchor,
                 duration: float, delay: int = 0, truth: TrueObstacles | None = None) -> None:
        self.plant = plant
        self.truth = truth
        self.anchor_mode = anchor
        self.dt_ns = seconds_to_ns(plant.dt)
        self.duration_ns = seconds_to_ns(duration)
        self.step_index = 0
        self.x = np.zeros(plant.n)
        self.x[:2] = np.asarray(start, dtype=float)[:2]
        self.anchor = np.array(self.x[:2])
        self.u = np.zeros(plant.m)
        self.delay = DelayLine(delay, plant.m)
        self.d = np.zeros(plant.q)
        self.rejected = 0
        self.paused = False

    @property
    def now_ns(self) -> int:
        """Sim time of the current state, ns."""
        return self.step_index * self.dt_ns

    @property
    def contact(self) -> tuple[str, ...]:
        """Obstacles the robot touched during the last step (physics plant; else none)."""
        return self.plant.contact if isinstance(self.plant, MujocoPlant) else ()

    @property
    def finished(self) -> bool:
        """The duration has run out."""
        return bool(self.duration_ns) and self.now_ns >= self.duration_ns

    def hold_force(self, u: npt.ArrayLike) -> bool:
        """Hold ``u`` (N) over the next steps; False when it was not finite (zero is held)."""
        force = np.asarray(u, dtype=float)
        if np.all(np.isfinite(force)):
            self.u = force
            return True
        self.rejected += 1
        self.u = np.zeros(self.plant.m)
        return False

    def hold_disturbance(self, d: npt.ArrayLike) -> bool:
        """Hold ``d``; False when it was not finite or not of size q (zero is held)."""
        value = np.asarray(d, dtype=float)
        if value.shape == self.d.shape and np.all(np.isfinite(value)):
            self.d = value
            return True
        self.rejected += 1
        self.d = np.zeros(self.plant.q)
        return False

    def follow_target(self, target: npt.ArrayLike) -> None:
        """The controller's leg target (m): the spring's anchor when it is ``leg_target``."""
        if self.anchor_mode is SpringAnchor.LEG_TARGET:
            self.anchor = np.asarray(target, dtype=float)

    def advance(self) -> bool:
        """One step with the held disturbance and the force held ``delay`` steps ago.

        False when paused or finished.
        """
        if self.paused or self.finished:
            return False
        anchor = self.anchor if self.anchor_mode is SpringAnchor.LEG_TARGET else np.zeros(2)
        if self.truth is not None and isinstance(self.plant, MujocoPlant):
            existing = self.truth.update(self.x[:2], self.now_ns * 1e-9)
            self.plant.set_present(spec.id for spec in existing)
        self.x = self.plant.step(self.x, self.delay.shift(self.u), self.d, anchor)
        self.step_index += 1
        return True
