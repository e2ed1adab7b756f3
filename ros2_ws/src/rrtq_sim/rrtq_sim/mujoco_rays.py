"""The laser scanner's rays cast by MuJoCo (``mj_multiRay``) in the physics plant's own world.

With ``plant.model: mujoco`` the scan is cast against the same MuJoCo model the plant steps
(:func:`rrtq_sim.mujoco_model.build_model`): the scenario's obstacles as static prisms and,
with ``plant.mjcf``, whatever the user's file holds besides its robot (walls, furniture).
The rays are horizontal, from the base's centre at its height; the robot's own geoms (the
base and every body below it) are not seen, nor are obstacles that do not exist at the
step. MuJoCo's ray functions skip geoms whose colour is fully transparent, so this model
is a copy of the plant's used for rays alone: the robot's geoms and absent obstacles get
alpha 0 here, never in the model that is stepped.

Against the shipped base the ranges equal :func:`rrtq_sim.scan.cast_rays`' on the same
polygons within MuJoCo's single-precision mesh vertices (``tests/test_scan.py``). No ROS
import.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
import numpy.typing as npt

from rrtq_common.world import ObstacleSpec
from rrtq_sim.mujoco_model import (BASE_BODY, BaseParameters, build_model, obstacle_geom_name,
                                   obstacle_pieces, planar_dofs, robot_geoms)

__all__ = ['MujocoRays']

_TIMESTEP = 1e-3
"""s; the ray model is never stepped, but MuJoCo needs a step to compile."""


class MujocoRays:
    """A ray caster over the plant's MuJoCo world (:class:`rrtq_sim.scan.RayCaster`).

    Parameters
    ----------
    obstacles : sequence of ObstacleSpec
        Every obstacle of the scenario (which exist is given at each cast).
    base : BaseParameters, optional
        The shipped planar base (when ``mjcf`` is None); only its radius matters here.
    mjcf : str, optional
        A user's MJCF file (:mod:`rrtq_sim.mujoco_model` says what it must contain).

    Raises
    ------
    rrtq_sim.mujoco_model.MjcfError
        The file cannot be used.
    """

    def __init__(self, obstacles: Sequence[ObstacleSpec], base: BaseParameters | None = None,
                 mjcf: str | None = None) -> None:
        self.model = build_model(obstacles, _TIMESTEP, base, mjcf)
        self.data = mujoco.MjData(self.model)
        model = self.model
        self._body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, BASE_BODY)
        self._qpos, _ = planar_dofs(model, self._body)
        mujoco.mj_kinematics(model, self.data)
        self._offset = self.data.xpos[self._body][:2] - self.data.qpos[self._qpos]
        for g in robot_geoms(model, self._body):
            model.geom_rgba[g, 3] = 0.0
        self._geoms = {o.id: [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM,
                                                obstacle_geom_name(o.id, k))
                              for k in range(len(obstacle_pieces(o.polygon)))]
                       for o in obstacles}
        self._present: frozenset[str] | None = None

    def _show(self, present: frozenset[str]) -> None:
        if present == self._present:
            return
        for oid, geoms in self._geoms.items():
            self.model.geom_rgba[geoms, 3] = 1.0 if oid in present else 0.0
        self._present = present

    def __call__(self, origin: npt.ArrayLike, directions: np.ndarray,
                 obstacles: Sequence[ObstacleSpec], range_max: float) -> np.ndarray:
        """Ranges (m) along ``directions`` (N, 2) from ``origin`` (m), ``+inf``: no hit.

        ``obstacles`` are those that exist now (by id; their polygons are the model's).
        """
        o = np.asarray(origin, dtype=float).reshape(2)
        d = np.asarray(directions, dtype=float).reshape(-1, 2)
        self._show(frozenset(spec.id for spec in obstacles))
        self.data.qpos[self._qpos] = o - self._offset
        mujoco.mj_kinematics(self.model, self.data)
        point = np.array([o[0], o[1], self.data.xpos[self._body][2]])
        vectors = np.c_[d, np.zeros(len(d))].ravel()
        geom = np.zeros(len(d), dtype=np.int32)
        dist = np.zeros(len(d))
        mujoco.mj_multiRay(self.model, self.data, point, vectors, None, 1, -1, geom, dist,
                           None, len(d), float(range_max))
        return np.where((dist >= 0.0) & (dist <= range_max), dist, np.inf)
