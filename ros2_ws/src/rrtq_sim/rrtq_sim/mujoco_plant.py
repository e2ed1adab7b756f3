"""The physics plant: a planar base stepped by MuJoCo among the scenario's obstacles.

:class:`MujocoPlant` has :class:`rrtq_sim.plant.Plant`'s step interface, so
:class:`rrtq_sim.simulation.Simulation` runs either. The state is the rover's,
x = (p_x, p_y, v_x, v_y) of the base body in the world frame; the force is saturated and
held over Δt as the controls of the actuators ``fx`` and ``fy``, taken in
:data:`rrtq_sim.mujoco_model.SUBSTEPS` MuJoCo steps. The disturbance d enters as the linear
plant's does, through the velocity rows of F: an acceleration, applied to the base as the
external force ``xfrc_applied`` = (mass of the base and what it carries) x (F d)[2:4].

An obstacle is physical: touching one is a contact, which MuJoCo resolves (the base stops
or slides along it) and which the plant reports (:attr:`MujocoPlant.contact`) — for the
run, a collision. Obstacles that do not exist at a step are switched off
(:meth:`MujocoPlant.set_present`: their geoms' contype and conaffinity are 0).

Determinism: MuJoCo on one thread is a function of its inputs; two plants fed the same
sequence give bit-identical states.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import mujoco
import numpy as np
import numpy.typing as npt

from rrtq_common.world import ObstacleSpec
from rrtq_sim.mujoco_model import (ACTUATORS, BASE_BODY, SUBSTEPS, BaseParameters,
                                   build_model, obstacle_geom_name, obstacle_pieces,
                                   planar_dofs, robot_geoms)

__all__ = ['MujocoPlant']


class MujocoPlant:
    """A MuJoCo model stepped Δt at a time under a held force and disturbance.

    Parameters
    ----------
    obstacles : sequence of ObstacleSpec
        The scenario's obstacles (all of them; :meth:`set_present` says which exist).
    dt : float
        Step length, s (> 0).
    force_limit : float
        Saturation per axis, N (> 0; ``inf``: none).
    F : array_like, shape (4, q), or None
        Disturbance matrix; its position rows must be zero (d is an acceleration).
    base : BaseParameters, optional
        The shipped planar base (when ``mjcf`` is None).
    mjcf : str, optional
        A user's MJCF file (:mod:`rrtq_sim.mujoco_model` says what it must contain).
    substeps : int
        MuJoCo steps per Δt.
    """

    n = 4
    m = 2

    def __init__(self, obstacles: Sequence[ObstacleSpec], dt: float, force_limit: float,
                 F: npt.ArrayLike | None, base: BaseParameters | None = None,
                 mjcf: str | None = None, substeps: int = SUBSTEPS) -> None:
        if not (np.isfinite(dt) and dt > 0.0):
            raise ValueError(f'dt must be finite and > 0, got {dt!r}')
        if not force_limit > 0.0:
            raise ValueError(f'force_limit must be > 0, got {force_limit!r}')
        if substeps < 1:
            raise ValueError(f'substeps must be >= 1, got {substeps}')
        f = np.zeros((self.n, 0)) if F is None else np.array(F, dtype=float, ndmin=2)
        if f.ndim != 2 or f.shape[0] != self.n or not np.all(np.isfinite(f)):
            raise ValueError(f'F must be finite with shape (4, q), got {f.shape}')
        if np.any(f[:2]):
            raise ValueError('F must have zero position rows: the disturbance is applied as '
                             'a force (an acceleration of the base)')
        self._f_accel = f[2:].copy()
        self._dt = float(dt)
        self._substeps = int(substeps)
        self._force_limit = float(force_limit)
        self.model = build_model(obstacles, dt / substeps, base, mjcf)
        self.data = mujoco.MjData(self.model)
        model = self.model
        self._body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, BASE_BODY)
        self._actuators = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
                           for name in ACTUATORS]
        self._qpos, self._qvel = planar_dofs(model, self._body)
        self.mass = float(model.body_subtreemass[self._body])
        mujoco.mj_forward(model, self.data)
        # World position of the base at the joints' zero: position = offset + qpos.
        self._offset = self.data.xpos[self._body][:2] - self.data.qpos[self._qpos]
        self._robot_geoms = robot_geoms(model, self._body)
        self._geom_obstacle: dict[int, str] = {}
        self._obstacle_geoms: dict[str, list[int]] = {}
        for obstacle in obstacles:
            for k in range(len(obstacle_pieces(obstacle.polygon))):
                geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM,
                                         obstacle_geom_name(obstacle.id, k))
                self._geom_obstacle[geom] = obstacle.id
                self._obstacle_geoms.setdefault(obstacle.id, []).append(geom)
        self._collides = {g: (int(model.geom_contype[g]), int(model.geom_conaffinity[g]))
                          for g in self._geom_obstacle}
        self.set_present(o.id for o in obstacles if o.exists(0.0))
        self._last: np.ndarray | None = None
        self.contact: tuple[str, ...] = ()
        """Ids of the obstacles the robot touched during the last step (sorted; empty: none)."""
        self.contact_steps = 0
        """Steps during which the robot touched an obstacle."""

    # -- the Plant interface ----------------------------------------------------
    @property
    def q(self) -> int:
        """Disturbance dimension."""
        return int(self._f_accel.shape[1])

    @property
    def dt(self) -> float:
        """Step length, s."""
        return self._dt

    @property
    def substeps(self) -> int:
        """MuJoCo steps per Δt."""
        return self._substeps

    @property
    def force_limit(self) -> float:
        """Saturation per axis, N."""
        return self._force_limit

    def saturate(self, u: npt.ArrayLike) -> np.ndarray:
        """Clip each force component to ``[-force_limit, force_limit]``, N.

        Raises
        ------
        ValueError
            If ``u`` has the wrong shape or is not finite.
        """
        uu = np.asarray(u, dtype=float).reshape(-1)
        if uu.shape != (self.m,):
            raise ValueError(f'u must have shape ({self.m},), got {np.shape(u)}')
        if not np.all(np.isfinite(uu)):
            raise ValueError(f'u must be finite, got {uu}')
        return np.clip(uu, -self._force_limit, self._force_limit)

    def state(self) -> np.ndarray:
        """The base's (p_x, p_y, v_x, v_y) now, m and m/s (world frame)."""
        return np.concatenate([self._offset + self.data.qpos[self._qpos],
                               self.data.qvel[self._qvel]])

    def set_present(self, ids: Iterable[str]) -> None:
        """Make exactly the obstacles ``ids`` physical; the others' geoms collide with nothing."""
        present = set(ids)
        for oid, geoms in self._obstacle_geoms.items():
            for g in geoms:
                contype, conaffinity = self._collides[g] if oid in present else (0, 0)
                self.model.geom_contype[g] = contype
                self.model.geom_conaffinity[g] = conaffinity

    def step(self, x: npt.ArrayLike, u: npt.ArrayLike, d: npt.ArrayLike | None,
             anchor: npt.ArrayLike | None = None) -> np.ndarray:
        """Advance by one Δt with ``u`` and ``d`` held; returns the state after it.

        Parameters
        ----------
        x : array_like, shape (4,)
            The state to step from. The plant keeps MuJoCo's full state between steps;
            an ``x`` other than the one it last returned is written into the base's
            position and velocity (the rest of the model's state is kept).
        u : array_like, shape (2,)
            Force, N; saturated.
        d : array_like, shape (q,), or None
            Disturbance (None: zero).
        anchor : array_like, optional
            Unused (the physics plant has no spring); there for the Plant interface.

        Returns
        -------
        numpy.ndarray, shape (4,)
        """
        del anchor
        xx = np.asarray(x, dtype=float).reshape(-1)
        if xx.shape != (self.n,) or not np.all(np.isfinite(xx)):
            raise ValueError(f'x must be finite with shape (4,), got {xx}')
        dd = np.zeros(self.q) if d is None else np.asarray(d, dtype=float).reshape(-1)
        if dd.shape != (self.q,) or not np.all(np.isfinite(dd)):
            raise ValueError(f'd must be finite with shape ({self.q},), got {dd}')
        data = self.data
        if self._last is None or not np.array_equal(xx, self._last):
            data.qpos[self._qpos] = xx[:2] - self._offset
            data.qvel[self._qvel] = xx[2:]
        data.ctrl[self._actuators] = self.saturate(u)
        data.xfrc_applied[self._body, :2] = self.mass * (self._f_accel @ dd)
        touched: set[str] = set()
        for _ in range(self._substeps):
            mujoco.mj_step(self.model, data)
            touched.update(self._touched())
        self.contact = tuple(sorted(touched))
        self.contact_steps += bool(touched)
        self._last = self.state()
        return self._last.copy()

    def _touched(self) -> set[str]:
        """Obstacles in contact with the robot's geoms after the last MuJoCo step."""
        out = set()
        for i in range(self.data.ncon):
            contact = self.data.contact[i]
            pair = (int(contact.geom1), int(contact.geom2))
            for mine, other in (pair, pair[::-1]):
                if mine in self._robot_geoms and other in self._geom_obstacle:
                    out.add(self._geom_obstacle[other])
        return out
