"""The vf_lpc variant as the controller node drives it: reference + obstacles -> force.

Each step: the transition just completed, (x_{k-1}, u_{k-1}, x_k), is fed to the sparse
GP (eq. 18) and the prediction made for x_k at the step before is scored against it (the
state's ``prediction_error``, ``nominal_error``, ``prediction_std``); then the
receding-horizon actor-critic (:class:`VFLPCController`) tracks the first N + 1 samples of
the guidance reference under the barrier of the nearest augmented obstacles, and its first
input, saturated to the actuator's limit, is the command. No reference yet: zero force.

What :class:`ControlOutput`'s leg fields mean here (docs/vf_lpc.md, "In the graph"): the
"leg" is the reference over the controller's horizon, from its first sample (``leg_start``)
to sample N (``leg_target``); ``leg_index`` counts the guidance's rollouts of its curve,
``leg_start_time`` is when the current one was first tracked, ``d0`` is the horizon's chord
|r_N - r_0|, ``d`` and ``tracking_error`` the robot's distance to r_0, ``time_to_go`` the
horizon N dt; so the safety node's D_rob is the robot's distance from the chord's line,
how far it strays from what it is told to follow. ``actor_weights`` are the horizon's
planned inputs (N x m, row-major), ``critic_error`` is left 0 and ``horizon_cost`` carries
the optimised cost.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rrtq_common.lockstep import OnChange

from ..config import ControllerConfig
from ..driver import ControlOutput, Driver
from .config import LPCConfig
from .controller import VFLPCController
from .koopman import KoopmanModel

Array = NDArray[np.float64]

__all__ = ['VFLPCDriver']


class VFLPCDriver(Driver):
    """VF-LPC on the model file ``config.model``, configured by ``lpc``.

    Parameters
    ----------
    config : ControllerConfig
        ``model`` names the file (``rrtq identify``), ``force_limit`` bounds every input.
    n, m, q : int
    rng : numpy.random.Generator
        Unused: the variant has no randomness (lock-step runs repeat exactly).
    lpc : LPCConfig
        The solver's settings; its ``force_limit`` is replaced by ``config.force_limit``.
    """

    def __init__(self, config: ControllerConfig, n: int, m: int, q: int,
                 rng: np.random.Generator, lpc: LPCConfig | None = None) -> None:
        super().__init__(config, n, m, q, rng)
        model = KoopmanModel.load(config.model)
        if (model.n, model.m) != (n, m):
            raise ValueError(f'{config.model}: a model of {model.n} states and {model.m} '
                             f'inputs, the plant has {n} and {m}')
        if not math.isfinite(config.force_limit):
            raise ValueError('the vf_lpc variant needs a finite force_limit')
        self.lpc = dataclasses.replace(lpc or LPCConfig(), force_limit=config.force_limit)
        self.controller = VFLPCController(model, self.lpc)
        self._reference: Array | None = None
        self._rollout = -1
        self._rollout_time = 0.0
        self._reference_stamp: int | None = None
        self._obstacles_stamp: int | None = None
        self._last: tuple[float, Array, Array] | None = None      # t, x, u applied
        self._predicted: tuple[Array, Array, Array] | None = None  # mean, std, nominal

    def set_plan(self, waypoints: ArrayLike, x: ArrayLike, t: float) -> None:
        """The waypoints are not followed: the guidance reference is (see set_guidance)."""

    def set_guidance(self, reference: OnChange[tuple[Array, int]] | None,
                     obstacles: OnChange[list[Array]] | None) -> None:
        """Take this step's reference (K, n) and rollout, and the augmented set if changed."""
        if obstacles is not None and obstacles.stamp_ns != self._obstacles_stamp:
            self._obstacles_stamp = obstacles.stamp_ns
            self.controller.set_obstacles(obstacles.read())
        if reference is not None and reference.stamp_ns != self._reference_stamp:
            self._reference_stamp = reference.stamp_ns
            states, rollout = reference.read()
            self._reference = np.asarray(states, dtype=float)
            if rollout != self._rollout:
                self._rollout, self._rollout_time = rollout, reference.stamp_ns * 1e-9

    def _score(self, t: float, x: Array) -> tuple[Array, Array, Array]:
        """Learn from the transition into x; the errors of the prediction made for it."""
        empty = np.zeros(0)
        last, predicted = self._last, self._predicted
        if last is None or predicted is None or not math.isclose(
                t - last[0], self.config.dt, rel_tol=1e-6, abs_tol=1e-9):
            return empty, empty, empty      # a gap (start, refused odometry): nothing to learn
        self.controller.observe(last[1], last[2], x)
        mean, std, nominal = predicted
        return x - mean, x - nominal, std

    def step(self, t: float, x: ArrayLike, d_applied: ArrayLike | None = None) -> ControlOutput:
        xx = np.asarray(x, dtype=float)
        prediction_error, nominal_error, std = self._score(t, xx)
        ref = self._reference
        N = self.lpc.horizon_steps
        if ref is None or not len(ref):
            u = np.zeros(self.m)
            ref = np.repeat(xx[None], N + 1, axis=0)
            ref[:, 2:] = 0.0
            event, cost, planned = 'no_plan', 0.0, np.zeros(0)
        else:
            u, solution = self.controller.step(xx, ref)
            event, cost, planned = 'continue', float(solution.cost), solution.inputs.ravel()
        mean, var = self.controller.predict(xx, u)
        self._predicted = (mean, np.sqrt(var), self.controller.nominal(xx, u))
        self._last = (t, xx.copy(), u.copy())
        start = ref[0, :2]
        target = ref[min(N, len(ref) - 1), :2]
        gp = self.controller.gp
        empty = np.zeros(0)
        return ControlOutput(
            u=u, leg_index=max(self._rollout, 0), leg_start_time=self._rollout_time,
            leg_start=start.copy(), leg_target=target.copy(),
            d0=float(np.hypot(*(target - start))), d=float(np.hypot(*(xx[:2] - start))),
            time_to_go=N * self.config.dt, probing=np.zeros(self.m), critic_weights=empty,
            actor_weights=planned, disturbance_weights=empty, critic_error=0.0,
            terminal_error=0.0, event=event,
            tracking_error=float(np.hypot(*(xx[:2] - start))),
            prediction_error=prediction_error, nominal_error=nominal_error,
            prediction_std=std, gp_dictionary=gp.size if gp is not None else 0,
            horizon_cost=cost)
