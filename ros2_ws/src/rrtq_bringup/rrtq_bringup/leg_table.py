"""Per-leg cost of a recorded run against the Riccati optimum of the true plant (no rclpy).

Issue 4's check, from the recording alone (``/odom``, ``/cmd_force``, ``/controller/state``,
``/disturbance`` and the scenario embedded in the file): for every leg its cost

    J = ½∫_leg (x̄ᵀMx̄ + uᵀRu) dt + ½ x̄_endᵀ P(τ_end) x̄_end,   τ_end = max(T - duration, 0),

i.e. the running cost over the leg plus the optimal cost-to-go from where it ended, is
compared with the optimum ½ x̄0ᵀ P(T) x̄0 of the same finite-horizon problem. A leg is a
maximal run of steps with the same ``leg_index``, D0 and target, so a leg restarted by a
new plan or by the horizon counts anew; steps without a plan (D0 = 0) belong to no leg.
The leg starts at its first step (x̄0 = x(t_start) − x_r) and ends where the next step
that is not its own was measured (the state the driver judged). Because J is
the cost of "what the robot did, then the optimal policy", J >= optimum for any leg,
however it ended (window, horizon restart, new plan, end of the recording), with equality
only when the robot acted optimally throughout. x̄ is the state relative to the leg
target at rest, u the applied force (the command saturated at the plant's force limit),
held over each step as the simulator holds it.

Quadrature (``quadrature='zoh'``, the default): over each step [t_k, t_k+1) the recorded
x̄_k, the held u_k and d_k determine the whole trajectory of the true plant, so the
running cost is integrated exactly by Van Loan's matrix exponential,
½∫ zᵀ diag(M, R, 0) z dt = ½ z_kᵀ Q_d z_k with z = (x̄, u, d, 1). ``'trapezoid'``
uses the samples only: the trapezoidal rule on x̄ᵀMx̄ plus u_kᵀRu_k Δt (exact for a held
u); its error is O(Δt²) (per leg within 5e-4 of the exact value on the spring-free
rover at Δt = 0.05 s, scenarios/rover_no_spring.yaml).
The residual between the recorded x̄_k+1 and the plant's prediction from (x̄_k, u_k, d_k)
is reported per leg, so a recording whose timing does not match the assumption shows.

The true plant comes from the embedded scenario. With ``spring_anchor: leg_target`` (or
``stiffness: 0``) the plant is x̄' = A x̄ + B u + F d in leg coordinates. With
``world_origin`` and a spring, x̄' = A x̄ + B u + F d + c with c = A x_r (the spring pulls
towards the origin, not the target), an affine problem: it is solved exactly by appending
a constant state 1 (A_z = [[A, c], [0, 0]], M_z = diag(M, 0), P_T,z = diag(P_T, 0)), so
the optimum and the cost-to-go are ½ zᵀP_z z with z = (x̄, 1) (they include the cost of
the force that holds the robot against the spring). The controller's linear actor cannot
represent the affine optimum there; its gain error is still taken against the linear
block R⁻¹BᵀP_xx, which is the Riccati gain R⁻¹BᵀP (the affine term does not change it).

The disturbance, when present, enters the running cost through the state it moves; the
optimum is the nominal LQR problem's (the robust game's −γ²‖d‖² term is not included).
Under a disturbance no policy reaches that optimum, so each leg is also flown, on the true
plant, by the true Riccati policy from the same x̄0 through the leg's recorded d_k and the
plant's saturation, over the recorded leg's steps, plus the cost-to-go from where it is
then (``riccati_policy_cost``; ``ratio_riccati_policy`` = cost over it, 1 for the optimal
feedback with or without a disturbance): the reference the random-plant bench holds the
learner to. With odometry noise and an actuation delay (``plant.odometry_noise``,
``plant.actuation_delay``) the reference is handicapped as the robot was: it sees the
state with the noise the robot's odometry had at each step (/odom − /odom/truth) and its
commands act ``delay`` steps late, the first ones of the leg taken by the forces already
commanded. The cost itself is always of the true state (/odom/truth when recorded) and
the force the plant applied (the command ``delay`` steps before).

Gain error: with the actor weights Ŵa ((L n) x m) published every step and the time
basis φ(τ) recorded beside them (:class:`rrtq_controller.basis.TimeBasis`), the learned
gain is K̂(τ) = −Σ_l φ_l(τ) Ŵa,lᵀ (û = Ŵaᵀ(φ(τ)⊗x̄) = −K̂x̄); per leg the mean over its
steps of ‖K̂(τ_k) − R⁻¹BᵀP(τ_k)‖_F / ‖R⁻¹BᵀP(τ_k)‖_F.

``python -m rrtq_bringup.leg_costs RUN.mcap [--json]`` prints the table (or the summary).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rrtq_bringup.leg_model import LegModel, time_basis_of
from rrtq_bringup.leg_steps import align_steps
from rrtq_bringup.scenario import Scenario
from rrtq_common.actor import actor_gain
from rrtq_controller.basis import TimeBasis
from rrtq_sim.plant import SpringAnchor

__all__ = ['Quadrature', 'QUADRATURES', 'LegEnd', 'LegRow', 'LegTable', 'leg_table', 'summary',
           'format_table']

Array = NDArray[np.float64]


class Quadrature(enum.StrEnum):
    """How the running cost of a step is integrated (see the module doc)."""

    ZOH = 'zoh'
    """Exactly, with the inputs held over the step (Van Loan)."""
    TRAPEZOID = 'trapezoid'
    """From the samples alone: the trapezoidal rule on x̄ᵀMx̄, uᵀRu held."""


QUADRATURES = tuple(q.value for q in Quadrature)


class LegEnd(enum.StrEnum):
    """How a recorded leg ended."""

    WINDOW = 'window'
    """D <= ρ D0: the terminal-state window was reached."""
    HORIZON = 'horizon'
    """T elapsed."""
    SWITCH = 'switch'
    """A new plan started another leg."""
    END = 'end'
    """The recording ended."""


@dataclasses.dataclass(frozen=True)
class LegRow:
    """One leg of a recorded run and its cost against the optimum."""

    index: int
    """``leg_index`` of /controller/state."""
    start_time: float
    """s, sim time of the leg's first step."""
    duration: float
    """s, from the first step to the step where the next leg started (or the last sample)."""
    steps: int
    target: Array
    """(2,) m, the leg's waypoint."""
    x0_bar: Array
    """(n,) state at the start relative to the target at rest."""
    d0: float
    """‖x̄0‖ (RRT-QX (4))."""
    x_end_bar: Array
    """(n,) state where the leg ended, relative to its target."""
    tau_end: float
    """s, T − duration clipped at 0."""
    running_cost: float
    """½∫(x̄ᵀMx̄ + uᵀRu) dt over the leg."""
    cost_to_go: float
    """½ x̄_endᵀ P(τ_end) x̄_end (affine form with world_origin, see module doc)."""
    optimum: float
    """½ x̄0ᵀ P(T) x̄0."""
    gain_error: float
    """Mean relative Frobenius error of K̂(τ) over the leg's steps (nan: no actor weights)."""
    ended_by: LegEnd
    model_residual: float
    """max_k ‖x̄_k+1 − (plant prediction)‖ / max(‖x̄_k‖, 1e-3 m) over the leg."""
    riccati_policy_cost: float
    """The same leg flown by the true Riccati policy through the leg's recorded disturbance
    and the plant's saturation over the recorded leg's steps, plus the cost-to-go from
    there (see the module doc)."""

    @property
    def cost(self) -> float:
        """Running cost plus cost-to-go."""
        return self.running_cost + self.cost_to_go

    @property
    def ratio(self) -> float:
        """Leg cost over the optimum (>= 1; nan when the optimum is 0)."""
        return self.cost / self.optimum if self.optimum > 0 else math.nan

    @property
    def ratio_riccati_policy(self) -> float:
        """Leg cost over :attr:`riccati_policy_cost`: 1 for the optimal feedback, also under a disturbance.

        nan when that cost is 0.
        """
        c = self.riccati_policy_cost
        return self.cost / c if c > 0 else math.nan


@dataclasses.dataclass(frozen=True)
class LegTable:
    """All legs of a run, in order, with how they were evaluated."""

    rows: tuple[LegRow, ...]
    horizon: float
    """T, s."""
    quadrature: Quadrature
    anchor_note: str
    """How the spring anchor entered the leg problem."""

    def column(self, name: str) -> Array:
        """One field (or property) of every row as an array."""
        return np.array([getattr(r, name) for r in self.rows], dtype=float)


def _anchor_note(sc: Scenario) -> tuple[bool, str]:
    """Whether the leg problem is affine, and how the anchor entered it."""
    A = np.asarray(sc.plant.A)
    world = sc.plant.spring_anchor is SpringAnchor.WORLD_ORIGIN
    if world and bool(np.any(A[:, :2] != 0.0)):
        return True, ("world_origin with a spring: affine leg problem x̄' = A x̄ + B u + A x_r, "
                      'solved exactly with an appended constant state')
    if world:
        return False, "world_origin without a spring: x̄' = A x̄ + B u in leg coordinates"
    return False, "leg_target: x̄' = A x̄ + B u in leg coordinates (spring at the target)"


def _running_cost(mdl: LegModel, xb: Array, nxt: Array, u: Array, d: Array, times: Array,
                  quadrature: Quadrature) -> tuple[float, float]:
    """½∫(x̄ᵀMx̄ + uᵀRu) over the steps, and the largest relative one-step model residual."""
    running, resid = 0.0, 0.0
    for k in range(xb.shape[0]):
        dt = float(times[k + 1] - times[k])
        cost, predicted = mdl.step(xb[k], u[k], d[k], dt)
        resid = max(resid, float(np.linalg.norm(nxt[k] - predicted))
                    / max(float(np.linalg.norm(xb[k])), 1e-3))
        if quadrature is Quadrature.ZOH:
            running += cost
        else:
            a, b = xb[k], nxt[k]
            running += 0.5 * dt * (0.5 * (a @ mdl.M @ a + b @ mdl.M @ b) + u[k] @ mdl.R @ u[k])
    return running, resid


def _riccati_policy_cost(mdl: LegModel, x0: Array, d: Array, times: Array, T: float,
                         limit: float, noise: Array | None = None,
                         pending: Array | None = None) -> float:
    """Cost of the true Riccati policy from x̄0 through the recorded d_k, saturated at ``limit``.

    It flies the recorded leg's steps (``times``: their stamps and the leg's end), τ
    clipped at 0 as the controller clips it, and the optimal cost-to-go from where it is
    then completes it, as for the recorded leg: the same interval, the same disturbance.
    It sees the state as the robot's odometry did (``noise``: per step, what the odometry
    added to the truth) and its commands go through the same actuator delay: ``pending``
    holds the forces already commanded at the leg's start, applied over its first steps
    (one per step of delay), before its own.
    """
    x, cost = np.asarray(x0, dtype=float).copy(), 0.0
    queue = deque(np.asarray(pending if pending is not None else np.zeros((0, mdl.m)), dtype=float))
    for k in range(d.shape[0]):
        tau = max(T - float(times[k] - times[0]), 0.0)
        seen = x if noise is None else x + noise[k]
        queue.append(np.clip(mdl.policy(seen, tau), -limit, limit))
        step_cost, x = mdl.step(x, queue.popleft(), d[k], float(times[k + 1] - times[k]))
        cost += step_cost
    return cost + mdl.value(x, max(T - float(times[-1] - times[0]), 0.0))


def _gain_error(mdl: LegModel, actor_w: list[Array], taus: Array, basis: TimeBasis) -> float:
    """Mean ‖K̂(τ_k) − K(τ_k)‖_F / ‖K(τ_k)‖_F over the steps (nan without usable weights)."""
    errs = []
    for w, tau in zip(actor_w, taus):
        gain = actor_gain(w, basis.rates, basis.powers, basis.horizon, mdl.n, mdl.m)
        if gain is None:
            return math.nan
        K_hat = gain(float(tau))
        K = mdl.gain(float(tau))
        errs.append(float(np.linalg.norm(K_hat - K) / np.linalg.norm(K)))
    return float(np.mean(errs)) if errs else math.nan


def leg_table(data: Any, scenario: Scenario, quadrature: str = Quadrature.ZOH) -> LegTable:
    """Evaluate every leg of a run (see the module doc for the definitions).

    Parameters
    ----------
    data
        A :class:`rrtq_bringup.run_data.RunData` (or anything with its fields ``odom_t``,
        ``odom_x``, ``cmd_t``, ``cmd_u``, ``dist_t``, ``dist_d``, ``state_t``,
        ``leg_index``, ``leg_target``, ``d0``, ``actor_w``, and the time basis
        ``time_rates``, ``time_powers``, for reconstructing K̂(τ)).
    scenario
        The run's scenario: the true plant, the cost weights, T, ρ.
    quadrature
        ``'zoh'`` (exact under the held inputs) or ``'trapezoid'`` (samples only).

    Returns
    -------
    LegTable
    """
    if quadrature not in QUADRATURES:
        raise ValueError(f'quadrature must be one of {QUADRATURES}, got {quadrature!r}')
    rule = Quadrature(quadrature)
    sc = scenario
    A = np.asarray(sc.plant.A)
    n = A.shape[0]
    T, rho = sc.controller.horizon, sc.controller.rho
    basis = time_basis_of(data, T)
    affine, note = _anchor_note(sc)
    st = align_steps(data, sc)
    models: dict[tuple[float, ...], LegModel] = {}

    def model_for(xr: Array) -> LegModel:
        c = A @ xr if affine else np.zeros(n)
        key = tuple(np.round(c, 12))
        if key not in models:
            models[key] = LegModel(sc, c)
        return models[key]

    # A leg is a run of steps with the same index, D0 and target. Steps without a plan
    # (the driver reports D0 = 0, leg index 0 and its own position as the target) belong
    # to no leg, but end the leg before them.
    key = np.column_stack([st.leg, st.d0, st.target])
    bounds = np.flatnonzero(np.any(np.diff(key, axis=0) != 0, axis=1)) + 1
    starts = np.concatenate([[0], bounds]).astype(int)
    ends = np.concatenate([bounds, [st.t.size]]).astype(int)
    rows: list[LegRow] = []
    for s, e in zip(starts, ends):
        if not st.d0[s] > 0.0:
            continue
        xr = np.zeros(n)
        xr[:2] = st.target[s]
        mdl = model_for(xr)
        xb = st.x[s:e] - xr
        ended: LegEnd | None = None
        if e < st.t.size:
            t_end, x_end = float(st.t[e]), st.x[e] - xr
        elif st.tail is not None:
            t_end, x_end, ended = st.tail[0], st.tail[1] - xr, LegEnd.END
        else:
            t_end, x_end, ended = float(st.t[e - 1]), xb[-1], LegEnd.END
            xb, e = xb[:-1], e - 1
        nxt = np.vstack([xb[1:], x_end[None]])
        times = np.append(st.t[s:e], t_end)
        running, resid = _running_cost(mdl, xb, nxt, st.u[s:e], st.d[s:e], times, rule)
        duration = t_end - float(st.t[s])
        tau_end = max(T - duration, 0.0)
        x0 = xb[0] if xb.shape[0] else x_end
        d0 = float(np.linalg.norm(x0))
        if ended is None:
            if np.linalg.norm(x_end) <= rho * d0 * (1 + 1e-9) + 1e-12:
                ended = LegEnd.WINDOW
            elif duration >= T - 1e-6:
                ended = LegEnd.HORIZON
            else:
                ended = LegEnd.SWITCH
        taus = np.maximum(T - (st.t[s:e] - st.t[s]), 0.0)
        rows.append(LegRow(
            index=int(st.leg[s]), start_time=float(st.t[s]), duration=duration,
            steps=int(xb.shape[0]), target=st.target[s].copy(), x0_bar=x0.copy(), d0=d0,
            x_end_bar=np.asarray(x_end, dtype=float).copy(), tau_end=tau_end,
            running_cost=running, cost_to_go=mdl.value(x_end, tau_end),
            optimum=mdl.value(x0, T),
            gain_error=_gain_error(mdl, st.actor_w[s:e], taus, basis),
            ended_by=ended, model_residual=resid,
            riccati_policy_cost=_riccati_policy_cost(mdl, x0, st.d[s:e], times, T,
                                                     float(sc.plant.force_limit),
                                                     st.noise[s:e], st.u[s:s + st.delay])))
    return LegTable(tuple(rows), T, rule, note)


def summary(table: LegTable, last: int = 10) -> dict[str, Any]:
    """The check of issue 4 and the per-leg lists.

    ``median_ratio_last10`` is the median of cost/optimum over the last ``last`` legs
    (all legs that have an optimum > 0, including a final leg cut by the end of the
    recording: its cost-to-go term makes it comparable); ``median_ratio_last10_complete``
    leaves out legs ended by the recording.
    """
    rows = [r for r in table.rows if r.optimum > 0]
    complete = [r for r in rows if r.ended_by is not LegEnd.END]

    def med(rs: list[LegRow], attr: str) -> float | None:
        vals = [getattr(r, attr) for r in rs[-last:]]
        vals = [v for v in vals if not math.isnan(v)]
        return float(np.median(vals)) if vals else None

    return {
        'legs': len(table.rows),
        'horizon_s': table.horizon,
        'quadrature': table.quadrature,
        'anchor': table.anchor_note,
        'median_ratio_last10': med(rows, 'ratio'),
        'median_ratio_last10_complete': med(complete, 'ratio'),
        'ratios_last10': [r.ratio for r in rows[-last:]],
        'median_gain_error_last10': med(rows, 'gain_error'),
        'median_ratio_riccati_policy_last10': med(rows, 'ratio_riccati_policy'),
        'index': [r.index for r in table.rows],
        'start_time': [r.start_time for r in table.rows],
        'duration': [r.duration for r in table.rows],
        'd0': [r.d0 for r in table.rows],
        'x0_bar': [r.x0_bar.tolist() for r in table.rows],
        'running_cost': [r.running_cost for r in table.rows],
        'cost_to_go': [r.cost_to_go for r in table.rows],
        'cost': [r.cost for r in table.rows],
        'optimum': [r.optimum for r in table.rows],
        'ratio': [r.ratio for r in table.rows],
        'gain_error': [r.gain_error for r in table.rows],
        'ratio_riccati_policy': [r.ratio_riccati_policy for r in table.rows],
        'ended_by': [r.ended_by for r in table.rows],
        'max_model_residual': max((r.model_residual for r in table.rows), default=0.0),
    }


def format_table(table: LegTable) -> str:
    """A Markdown table of the legs."""
    lines = ['| leg | start s | dur s | D0 m | ended | running | to go | optimum | ratio '
             '| vs Riccati policy | gain err |', '|---|---|---|---|---|---|---|---|---|---|---|']
    for r in table.rows:
        lines.append(f'| {r.index} | {r.start_time:.2f} | {r.duration:.2f} | {r.d0:.2f} | '
                     f'{r.ended_by} | {r.running_cost:.1f} | {r.cost_to_go:.2f} | '
                     f'{r.optimum:.1f} | {r.ratio:.4f} | {r.ratio_riccati_policy:.4f} | '
                     f'{r.gain_error:.3f} |')
    return '\n'.join(lines)
