"""Integral action for a leg held short of its target (no rclpy, no model of the plant).

A state feedback u = -K x̄ holds a robot under a steady push F_d (a field it stands in, a
slope) at the offset where K_p x̄ balances the push, F_d / K_p from its target (28 N against
the Riccati gain's 22.4 N/m: 1.25 m on the rover), and a robot with Coulomb friction stops
wherever K x̄ no longer exceeds the friction (a zero initial gain never starts: its 20 N of
probing does not break 39 N of friction). Either way the leg runs its whole horizon, a new
leg toward the same waypoint starts from where the robot stands (RRT-QX Alg. 1: the
finite-horizon problem is posed anew), its window ρ D0 shrinks with D0, and the mission
never goes on. No learning fixes it: every linear state feedback, the optimal one too,
stops short (``benchmarks/results/riccati_gain.md``, the field bump: 14/20 goals).

:class:`HeldShort` is conditional integration, the classic anti-windup form of integral
action. It is armed by a leg that follows one which ran its horizon short of its window
(the event that says "held short"; nothing else arms it) -- toward the same waypoint or the
next: the planner moves the waypoint of a robot that stalls on (``stall_time``), so a robot
friction holds at its start gets a new waypoint each leg, and arming only toward the same
one never armed it at μ = 0.3 -- and it integrates, per axis i, only while the robot is
held along that axis: slower along it, either way, than it needs to be to cover its share
of the distance to the window in the time left of the leg, by more than odometry noise
explains, and not speeding up toward its target fast enough to become so,

    |v_i| + max(s_i (v_i - v'_i) - σ, 0) T / (l Δt) + z σ_v < |ê_i| (|p̄| - ρ D0) / max(τ, Δt)

(|p̄| the robot's distance from its target, ê the unit vector from the robot to it, s_i
the sign of ê_i, v' the velocity l steps earlier, l the lag a force takes to show, σ what
noise alone can add to a speed: :class:`rrtq_controller.guard.Sensing`; σ_v the odometry's
velocity noise and z its one-sided normal quantile at :data:`~rrtq_controller.guard.FALSE_ALARM`
(1 %), so a robot that moves as fast as it needs reads as held on at most 1 % of its steps;
τ the leg's time to go), adding ``rate`` Δt ê_i to the force's component i each such
step. So it grows until the robot moves
toward its target along every axis it must, whatever holds it (a push, friction), and
holds what it has while the robot moves or its feedback is still speeding it up (a
retried leg starts at rest; a feedback that moves the robot needs a time constant to show
it, and integrating through that would carry a bias into the rest of the leg). Per axis
because friction may be: MuJoCo's planar base has it per slide joint (a square), so a
force grown along ê breaks the axis it has more of first, and a rule that held the force
once the robot moved at all slid it along that axis alone, off its line (μ = 0.1, seed 0
of ``mujoco_friction.yaml``: the line watch braked it 0.26, 0.63 and 1.0 m off in its first
84 s, each brake dropping the force; seeds 0-5 reached their goals 3 times in 6, and 6 in
6 held per axis). It does not wind up while the robot moves along an axis, toward its
target or away: a robot a periodic push swings around its waypoint (its legs run their
horizon too, the window D <= ρ D0 counting the speed) is not held, and a first version that
integrated whenever the speed *toward* the target fell short did so through every half
period the push carried the robot away: on the 110 kg rover under the 0.1 Hz sinusoid 5 of
20 robots left the world against 1, last ten 1.28 against 1.02. The rate takes the
actuator's limit in one horizon (``limit`` / T): any hold the actuator can overcome is
overcome within one retried leg.

Two rules keep it from doing harm where the hold is gone or changes with the direction:

* past its target the force keeps no part pointing away from it (friction holds a robot
  that overshot as it held it short; a force still pushing on would have to unwind
  through twice the friction first: at μ = 0.3 the robot hunted ±1 m around its goal at
  ±150 N);
* toward another waypoint (the leg's window entered, or a new plan) the force starts
  from zero, and integral action stays armed: the force grows again wherever the robot is
  held there, at the rate above (39 N of friction in 0.4 s on the MuJoCo base). Carrying
  the force on instead (its part toward the new waypoint, 6e0d3f6) is faster under
  friction (MuJoCo μ = 0.1, 10 seeds: median 149 s to the goal, against 254 s) but carries
  a force grown once (noise made a speeding robot look held, or the zero gain before a
  model) from leg to leg with nothing to unwind it: last ten 1.185 on a noisy, delayed,
  white-push mission, 1.072 on the rover under white 1.0 m/s². Carrying only along the
  axes the robot starts the new leg held on, and disarming otherwise (08ea4ec), mended
  that but halved the goals at μ = 0.3: a robot friction lets go of reaches its next leg
  moving, carries nothing and waits a horizon there. A retry toward the same waypoint
  keeps what it has.

The safety shell owns the direction into an obstacle it keeps the robot off: while a
keep-off pushes (it pushed on the last step) the force grows by no part toward that
obstacle, only along its face or away from it. A leg on which a keep-off pushed arms
integral action only where the model's rollout (below) shows it ended elsewhere than its
own policy, keep-off forces included, would have taken it; without a model to tell, such
a leg arms nothing. Earlier a keep-off leg armed nothing at all and the force did not
grow while a keep-off pushed: that left a robot a push held short *along* an obstacle's
face where it stood (``robot_side``'s field bump, seed 9: 2.4 m short of its waypoint for
320 s, the keep-off pushing on 60-80 % of the steps against the bump's part toward the
face, the part along it holding the robot off its waypoint as F_d / K_p; reached at
128.6 s now). And before that, without either rule, a robot held in an obstacle's
keep-off zone short of a waypoint past its face armed integral action each horizon and
grew it to the actuator's limit against the keep-off (``test_held_short``), and on
``robot_side``'s noisy, delayed sinusoid (seed 3) the robot touched an obstacle, 0.9 mm
deep, 0.3 s after integral action armed on such a leg. Nor does a leg on which the safety
brake acted arm it: the brake, not a push, stopped the robot short (after a brake were 12
of 159 armings on the robot-side rows at 304c4b6; the rover under white 0.5 m/s², seed 8,
flew its last ten legs at 1.243 of the optimum). Nor is a robot that ended its leg where its own policy
would have taken it (the controller decides,
:meth:`rrtq_controller.q_learning.QLearningController.start_leg`): the leg's start flown
through the observer's identified model by the gains and the probing the leg applied, no
push, no friction, against where the robot stood at the leg's last step; held only where the
two lie farther apart than the window ρ D0 (a difference the leg would accept is none) and
than the model's unexplained part and the odometry's noise explain at 1 %. The
finite-horizon optimum of a plant whose force is dear (R large), or that is heavy and
lightly damped, ends its legs short of their window by design, and integral action armed
there drove it on: ``controller_robustness``, 22 of 40 random plants within 5 % of the
Riccati policy at e34d154 against 40 of 40 without integral action (39 of 40 with this
rule, 8c2290f). Nor is a robot no policy has yet driven through a leg: before any leg has
completed, a leg that ran its horizon arms integral action only where
the robot ended it at rest (the mean of its last readings below the brake's rest speed,
or under odometry noise below what that many readings of a robot at rest show with
probability 1 %, enough of them to bring that down to the rest speed). The zero gain's
probing walks a frictionless robot about and its legs run their horizon; armed there,
integral action took over from a learner that had not started (the noisy, delayed robot
side, seeds 0 and 10: last ten 2.347 and 1.778 against 1.008 and 1.023), while friction or
a push holds a robot still.

The safety brake and a revert drop the force and disarm it. On by default
(``controller.integral_action``). Two earlier forms of the held test were not: with the
needed speed over a whole horizon T, a robot friction holds approached each waypoint at
(|p̄| - ρ D0) / T, an exponential with time constant T that enters the window after the
leg's horizon or not at all (MuJoCo, μ = 0.1 and 0.3: 9/10 and 8/10 goals in 300 s,
medians 254 s and 281 s); without the noise allowance, a robot that moved as fast as it
needed read as held on a third of its steps under σ_v = 0.05 m/s, and the force grown on
them cost the noisy, delayed robot side its leg cost (last ten 1.060 undisturbed, 1.99 on
its worst seed, against 1.013 without integral action). The history and the measurements
are in docs/features.md (issue 32).

Beyond the papers, like the guard. The Bellman rows take the force applied, this part
included, so the critic stays consistent (as with the keep-off and the saturation).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .guard import Sensing
from .guard.forces import Z_FALSE_ALARM

Array = NDArray[np.float64]

__all__ = ['HeldShort']


@dataclass
class HeldShort:
    """The integral force of a leg that follows one held short (see the module).

    ``m`` inputs (the first ``m`` states are the position, the next ``m`` the velocity, as
    the rover's x̄ = (p - p_r, v)); ``rho`` the leg window's ρ; ``horizon`` T (s); ``dt`` Δt (s);
    ``limit`` the actuator's limit per axis (N; not finite: no integral action).
    """

    m: int
    rho: float
    horizon: float
    dt: float
    limit: float
    force: Array = field(init=False)
    """N (m,): what is added to the policy's force."""
    active: bool = False
    """Whether the force may grow on this leg (the last ran its horizon, or carried a force)."""
    window: float = 0.0
    """m: ρ D0 of this leg."""
    sensing: Sensing = field(default_factory=Sensing)
    """Odometry noise and actuation delay (the keep-offs' :class:`Sensing`)."""
    _recent: deque[Array] = field(default_factory=deque)

    def __post_init__(self) -> None:
        self.force = np.zeros(self.m)

    @property
    def rate(self) -> float:
        """N/s: the growth of the force while the robot is held (the limit in one horizon)."""
        return self.limit / self.horizon if math.isfinite(self.limit) else 0.0

    def start_leg(self, x0_bar: Array, retry: bool) -> None:
        """A new leg from x̄0; ``retry``: the last leg ran its horizon (short of its window)."""
        x0_bar = np.asarray(x0_bar, dtype=float)
        self.window = self.rho * float(np.linalg.norm(x0_bar))
        self._recent.clear()
        if self.rate <= 0.0:
            return
        # what still pushes toward this leg's waypoint is carried, the rest dropped
        offset = x0_bar[:self.m]
        distance = float(np.linalg.norm(offset))
        along = float(self.force @ (-offset / distance)) if distance > 0.0 else 0.0
        if retry and along > 0.0:
            self.force = along * (-offset / distance)
        else:
            self.force = np.zeros(self.m)
        self.active = retry or self.active

    def drop(self) -> None:
        """The brake acts (or the leg's policy was reverted): no integral force, until a retry."""
        self.force = np.zeros(self.m)
        self.active = False
        self._recent.clear()

    def __call__(self, x_bar: Array, blocked: Sequence[Array] = (),
                 time_left: float | None = None) -> Array:
        """N (m,): the integral force for this step at state x̄.

        ``blocked``: the unit normals n (from the obstacle toward the robot) a keep-off of
        the safety shell pushed along on the last step. The shell owns that direction: the
        force grows by no part toward such an obstacle (held against its face is not held
        short), only along it or away. ``time_left``: s, the leg's time to go τ (None: a
        whole horizon).
        """
        if not self.active:
            return self.force
        x = np.asarray(x_bar, dtype=float)
        offset = x[:self.m]
        distance = float(np.linalg.norm(offset))
        if distance <= 0.0:
            return self.force
        toward = -offset / distance
        away = float(self.force @ toward)
        if away < 0.0:                 # past the target: no force away from it (no hunting)
            self.force = self.force - away * toward
        velocity = x[self.m:2 * self.m] if x.size >= 2 * self.m else np.zeros(self.m)
        left = self.horizon if time_left is None else max(time_left, self.dt)
        needed = (distance - self.window) / left * np.abs(toward)
        self._recent.append(velocity.copy())
        lag = self.sensing.lag
        while len(self._recent) > lag + 1:
            self._recent.popleft()
        if len(self._recent) <= lag:
            return self.force          # what the last force did has not shown yet
        # m/s per axis: what the speed toward the target gains in a horizon at its present rate
        gain = np.maximum(np.sign(toward) * (velocity - self._recent[0])
                          - self.sensing.difference, 0.0) * self.horizon / (lag * self.dt)
        held = np.abs(velocity) + gain + Z_FALSE_ALARM * self.sensing.velocity_std < needed
        step = np.where(held, self.rate * self.dt * toward, 0.0)
        for n in blocked:                # no growth toward an obstacle the shell keeps off
            into = float(step @ n)
            if into < 0.0:
                step = step - into * np.asarray(n, dtype=float)
        if step.any():
            grown = self.force + step
            size = float(np.linalg.norm(grown))
            self.force = grown if size <= self.limit else grown * (self.limit / size)
        return self.force
