"""Offline closed loop of VF-LPC (no ROS): RRT^X path -> guidance -> vf_lpc -> exact plant.

For fast tests and the model-mismatch study. The plant is :class:`rrtq_sim.plant.Plant`
(exact zero-order hold), optionally with acceleration bumps where the robot passes: the
disturbance field of :mod:`rrtq_sim.field` (the ``disturbance: field`` model), applied
through its input matrix E = [0; I] (m/s²). The controller sees only the identified
model, its own observations and the augmented obstacles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_controller.vf_lpc import KoopmanModel, LPCConfig, VFLPCController, fit_edmd
from rrtq_common.polygon_set import PolygonSet
from rrtq_planner import routes
from rrtq_planner.guidance import GuidanceConfig, GuidanceTrack
from rrtq_planner.shortcut import Shortener
from rrtq_sim.field import Bump, DisturbanceField, field_input_matrix
from rrtq_sim.plant import Plant, rover_matrices

__all__ = ['Bump', 'HarnessResult', 'identify_by_probing', 'plan_path', 'rover_plant',
           'run_closed_loop']


def rover_plant(mass: float, damping: float = 45.0, dt: float = 0.05,
                force_limit: float = 1000.0) -> Plant:
    """The rover without a spring (the controller does all the work)."""
    a, b = rover_matrices(mass, 0.0, damping)
    return Plant(a, b, field_input_matrix(4), dt, force_limit)


def identify_by_probing(plant: Plant, rng: np.random.Generator, seconds: float = 30.0,
                        hold: float = 0.5, amplitude: float = 400.0) -> KoopmanModel:
    """A recording's worth of probing (random piecewise-constant forces), fitted by EDMD."""
    steps = int(round(seconds / plant.dt))
    per = max(int(round(hold / plant.dt)), 1)
    forces = np.repeat(rng.uniform(-amplitude, amplitude, (steps // per + 1, plant.m)),
                       per, axis=0)[:steps]
    x = np.zeros(plant.n)
    xs, xn = [], []
    for u in forces:
        nxt = plant.step(x, u, None, np.zeros(2))
        xs.append(x)
        xn.append(nxt)
        x = nxt
    return fit_edmd(np.array(xs), forces, np.array(xn), plant.dt, 'linear',
                    force_limit=plant.force_limit)


@dataclass
class HarnessResult:
    """What one closed-loop run did (arrays per control step)."""

    reached: bool
    collided: bool
    time_s: float
    positions: np.ndarray
    commands: np.ndarray
    min_clearance: float
    tracking_error: np.ndarray            # m, robot to the reference's first point
    nominal_error: np.ndarray             # (K, n) x_{k+1} - nominal prediction
    learned_error: np.ndarray             # (K, n) x_{k+1} - learned (compensated) mean
    learned_std: np.ndarray               # (K, n) its predictive std (latent)
    step_ms: np.ndarray
    path: np.ndarray


def plan_path(obstacles: Sequence[np.ndarray], start: np.ndarray, goal: np.ndarray,
              bounds: tuple[float, float, float, float], iterations: int,
              seed: int) -> np.ndarray:
    """RRT^X path on the augmented obstacles after a fixed iteration count, shortened."""
    planner = routes.make_planner(list(obstacles), start, goal, bounds, 0.0, seed)
    planner.run(iterations)
    return routes.shortest_route(planner, start, Shortener(list(obstacles)))


def run_closed_loop(plant: Plant, model: KoopmanModel, truth: Sequence[npt.ArrayLike],
                    start: npt.ArrayLike, goal: npt.ArrayLike,
                    bounds: tuple[float, float, float, float], *, robot_radius: float = 0.5,
                    margin: float = 0.3, lpc: LPCConfig | None = None,
                    guidance: GuidanceConfig | None = None, bumps: Sequence[Bump] = (),
                    duration: float = 120.0, goal_tolerance: float = 0.3,
                    iterations: int = 1500, seed: int = 0,
                    clock=None) -> HarnessResult:
    """Plan, guide and control from ``start`` to ``goal`` around the true obstacles.

    The augmented obstacles are the true ones grown by ``robot_radius + margin``;
    collisions are judged against the true ones grown by ``robot_radius``.
    ``clock`` (a ``time.perf_counter``-like callable) times each control step.
    """
    lpc = lpc or LPCConfig(force_limit=plant.force_limit)
    guidance = guidance or GuidanceConfig(mode='gvf', dt=plant.dt)
    true_polys = [np.asarray(p, dtype=float) for p in truth]
    augmented = routes.grow(true_polys, robot_radius + margin)
    referee = PolygonSet(true_polys)
    field = DisturbanceField(bumps)
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    path = plan_path(augmented, start, goal, bounds, iterations, seed)
    track = GuidanceTrack(path, augmented, guidance)
    ctrl = VFLPCController(model, lpc)
    ctrl.set_obstacles(augmented)
    x = np.zeros(plant.n)
    x[:2] = start
    rec: dict[str, list] = {k: [] for k in ('p', 'u', 'track', 'nom', 'lrn', 'std', 'ms')}
    min_clear = np.inf
    reached = collided = False
    steps = int(round(duration / plant.dt))
    t = 0.0
    for k in range(steps):
        t = k * plant.dt
        ref = track.reference(x[:2], x[2:4], t)
        t0 = clock() if clock else 0.0
        u, _ = ctrl.step(x, ref.states)
        rec['ms'].append((clock() - t0) * 1e3 if clock else 0.0)
        mean_nom = ctrl.nominal(x, u)
        mean, var = ctrl.predict(x, u)
        x_next = plant.step(x, u, field.acceleration(x[:2]), np.zeros(2))
        ctrl.observe(x, u, x_next)
        rec['p'].append(x[:2].copy())
        rec['u'].append(u)
        rec['track'].append(float(np.hypot(*(x[:2] - ref.positions[0]))))
        rec['nom'].append(x_next - mean_nom)
        rec['lrn'].append(x_next - mean)
        rec['std'].append(np.sqrt(var))
        x = x_next
        clear = referee.nearest(x[:2])[0] - robot_radius
        min_clear = min(min_clear, clear)
        if clear < 0.0:
            collided = True
            break
        if np.hypot(*(x[:2] - goal)) <= goal_tolerance:
            reached = True
            break
    arr = {k: np.array(v) for k, v in rec.items()}
    return HarnessResult(reached, collided, t + plant.dt, arr['p'], arr['u'],
                         float(min_clear), arr['track'], arr['nom'], arr['lrn'], arr['std'],
                         arr['ms'], path)
