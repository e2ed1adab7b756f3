"""The MuJoCo model of ``plant.model: mujoco``: the planar base among the obstacles as geoms.

Two sources of the robot (docs/design.md, "Plant: mujoco"):

- the shipped planar base (:func:`base_mjcf`): a body ``base`` on two slide joints ``x``
  and ``y`` along the world axes, a cylinder of the robot's radius carrying the mass,
  viscous damping as the joints' ``damping`` and Coulomb friction as their
  ``frictionloss`` (N per axis), gravity off, two motors ``fx`` and ``fy``;
- a user's MJCF file (``plant.mjcf``): any model with a body named ``base`` that moves in
  the plane by two slide joints named ``x`` and ``y`` (axes along world x and y) or by a
  free joint, and two actuators named ``fx`` and ``fy`` whose controls are the forces, N,
  along world x and y.

Every obstacle of the scenario becomes static geoms of the world body
(:func:`obstacle_pieces`): a convex polygon one vertical prism, a non-convex one the
prisms of its constrained Delaunay triangles. No ROS import.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import shapely

from rrtq_common.world import ObstacleSpec

__all__ = ['BASE_BODY', 'GRAVITY', 'ACTUATORS', 'SLIDE_JOINTS', 'MIN_RADIUS', 'PRISM_Z',
           'SUBSTEPS', 'coulomb_force', 'BaseParameters', 'MjcfError', 'base_mjcf', 'obstacle_pieces', 'build_model',
           'obstacle_geom_name', 'planar_dofs', 'robot_geoms']

BASE_BODY = 'base'
"""The body whose world position is the robot's (x, y)."""
ACTUATORS = ('fx', 'fy')
"""The two actuators that take the force along world x and y, N."""
SLIDE_JOINTS = ('x', 'y')
"""The base's slide joints (or the base has a free joint)."""
MIN_RADIUS = 1e-3
"""m; the shipped base's cylinder when the scenario's robot radius is 0 (a point robot)."""
PRISM_Z = (-1.0, 2.0)
"""m; the vertical extent of every obstacle prism (covers a user's base standing on z = 0)."""
SUBSTEPS = 10
"""MuJoCo steps per plant step Δt (RK4: 5e-12 m from the exact rover over 200 steps of 0.05 s)."""


class MjcfError(ValueError):
    """A user's MJCF file that cannot be used: unreadable, invalid, or missing a named part."""


@dataclass(frozen=True)
class BaseParameters:
    """The shipped planar base.

    Attributes
    ----------
    mass : float
        kg (> 0).
    damping : float
        Viscous damping per axis, kg/s (N per m/s).
    friction : float
        Coulomb friction per axis, N: the largest force the base resists at rest.
    radius : float
        m; the cylinder's (at least :data:`MIN_RADIUS`).
    """

    mass: float
    damping: float
    friction: float
    radius: float


GRAVITY = 9.81
"""m/s², for the friction coefficient's normal force (the model itself has gravity off)."""


def coulomb_force(mu: float, mass: float) -> float:
    """The Coulomb friction force per axis, N, of coefficient ``mu`` on a base of ``mass`` kg.

    The planar base has no contact with a floor (gravity off: the slide joints carry it),
    so the scenario's coefficient becomes the joints' friction loss mu m g, per axis (a
    friction square where a floor would give a disc of the same radius).
    """
    return float(mu) * float(mass) * GRAVITY


def base_mjcf(base: BaseParameters, timestep: float) -> str:
    """The MJCF text of the shipped planar base (no obstacles), MuJoCo step ``timestep`` (s).

    RK4 integrates the free motion to the rover's exact solution within ~1e-11 m at ten
    substeps of 0.05 s; ``noslip_iterations`` makes the joints' friction loss exact
    Coulomb friction (without it the soft constraint lets a base pushed below its
    friction level creep, about 4 mm in 10 s at 75 % of the level).
    """
    radius = max(float(base.radius), MIN_RADIUS)
    return f"""<mujoco model="rrtq_planar_base">
  <option timestep="{timestep!r}" gravity="0 0 0" integrator="RK4" noslip_iterations="20"/>
  <worldbody>
    <body name="{BASE_BODY}">
      <joint name="x" type="slide" axis="1 0 0" damping="{base.damping!r}"
             frictionloss="{base.friction!r}"/>
      <joint name="y" type="slide" axis="0 1 0" damping="{base.damping!r}"
             frictionloss="{base.friction!r}"/>
      <geom name="{BASE_BODY}" type="cylinder" size="{radius!r} 0.1" mass="{base.mass!r}"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="fx" joint="x"/>
    <motor name="fy" joint="y"/>
  </actuator>
</mujoco>
"""


def obstacle_geom_name(obstacle_id: str, piece: int) -> str:
    """The name of the geom of piece ``piece`` of obstacle ``obstacle_id``."""
    return f'obstacle/{obstacle_id}/{piece}'


def obstacle_pieces(polygon: np.ndarray) -> list[np.ndarray]:
    """Convex pieces (each (k, 2), m) whose union is ``polygon`` (k, 2).

    A convex polygon is its own piece; a non-convex one is split into the triangles of
    its constrained Delaunay triangulation (the prisms MuJoCo collides are convex hulls).
    """
    shape = shapely.Polygon(np.asarray(polygon, dtype=float))
    hull = shape.convex_hull
    if isinstance(hull, shapely.Polygon) and hull.area - shape.area <= 1e-9 * max(hull.area, 1.0):
        return [np.array(hull.exterior.coords)[:-1]]
    triangles = shapely.constrained_delaunay_triangles(shape)
    return [np.array(t.exterior.coords)[:-1] for t in getattr(triangles, 'geoms', [triangles])
            if isinstance(t, shapely.Polygon) and t.area > 0.0]


def _add_obstacles(spec: mujoco.MjSpec, obstacles: Sequence[ObstacleSpec]) -> None:
    low, high = PRISM_Z
    for obstacle in obstacles:
        for k, piece in enumerate(obstacle_pieces(obstacle.polygon)):
            name = obstacle_geom_name(obstacle.id, k)
            vertices = np.concatenate([np.c_[piece, np.full(len(piece), low)],
                                       np.c_[piece, np.full(len(piece), high)]])
            spec.add_mesh(name=name, uservert=vertices.ravel().tolist())
            spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name)


def _check_parts(model: mujoco.MjModel, source: str) -> None:
    """Raise :class:`MjcfError` unless ``model`` has the base, its joints and the actuators."""
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, BASE_BODY) < 0:
        raise MjcfError(f'{source}: no body named {BASE_BODY!r}')
    for name in ACTUATORS:
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name) < 0:
            raise MjcfError(f'{source}: no actuator named {name!r} (the force along world '
                            f'{name[1]}, N)')
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, BASE_BODY)
    kinds = {int(model.jnt_type[j]) for j in range(model.njnt) if model.jnt_bodyid[j] == body}
    slides = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in SLIDE_JOINTS]
    if int(mujoco.mjtJoint.mjJNT_FREE) in kinds:
        return
    for name, joint in zip(SLIDE_JOINTS, slides):
        if joint < 0 or model.jnt_bodyid[joint] != body or \
                model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_SLIDE:
            raise MjcfError(f'{source}: body {BASE_BODY!r} needs a free joint or a slide '
                            f'joint named {name!r}')
        axis = np.zeros(3)
        axis['xy'.index(name)] = 1.0
        if not np.allclose(model.jnt_axis[joint], axis):
            raise MjcfError(f'{source}: slide joint {name!r} must be along world {name} '
                            f'(axis {axis.tolist()}), got {model.jnt_axis[joint].tolist()}')


def build_model(obstacles: Sequence[ObstacleSpec], timestep: float,
                base: BaseParameters | None = None, mjcf: str | None = None) -> mujoco.MjModel:
    """Compile the plant's model: the shipped ``base`` or the file ``mjcf``, with the obstacles.

    Parameters
    ----------
    obstacles : sequence of ObstacleSpec
        Every obstacle of the scenario (present or not: absent ones are switched off).
    timestep : float
        MuJoCo's step, s (a user's file's own timestep is replaced).
    base : BaseParameters, optional
        The shipped planar base (when ``mjcf`` is None).
    mjcf : str, optional
        Path of a user's MJCF file.

    Raises
    ------
    MjcfError
        The file is missing, unreadable, invalid MJCF, or lacks a named part.
    """
    if not (math.isfinite(timestep) and timestep > 0.0):
        raise ValueError(f'timestep must be finite and > 0, got {timestep!r}')
    if mjcf is None:
        if base is None:
            raise ValueError('either base or mjcf is needed')
        spec = mujoco.MjSpec.from_string(base_mjcf(base, timestep))
        source = 'the shipped base'
    else:
        if not os.path.isfile(mjcf):
            raise MjcfError(f'no such file: {mjcf}')
        try:
            spec = mujoco.MjSpec.from_file(mjcf)
        except Exception as exc:  # mujoco raises ValueError or its own errors
            raise MjcfError(f'{mjcf}: not a valid MJCF model ({exc})') from None
        spec.option.timestep = timestep
        source = mjcf
    _add_obstacles(spec, obstacles)
    try:
        model = spec.compile()
    except Exception as exc:
        raise MjcfError(f'{source}: does not compile ({exc})') from None
    _check_parts(model, source)
    return model


def planar_dofs(model: mujoco.MjModel, body: int) -> tuple[list[int], list[int]]:
    """The qpos and qvel addresses of ``body``'s x and y: its slide joints, else its free joint."""
    joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in SLIDE_JOINTS]
    if all(j >= 0 and model.jnt_bodyid[j] == body
           and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE for j in joints):
        return ([int(model.jnt_qposadr[j]) for j in joints],
                [int(model.jnt_dofadr[j]) for j in joints])
    free = next(j for j in range(model.njnt) if model.jnt_bodyid[j] == body
                and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
    qpos, dof = int(model.jnt_qposadr[free]), int(model.jnt_dofadr[free])
    return [qpos, qpos + 1], [dof, dof + 1]


def robot_geoms(model: mujoco.MjModel, body: int) -> frozenset[int]:
    """The geoms of ``body`` and of every body below it (the robot's own parts)."""

    def below(b: int) -> bool:
        while b > 0:
            if b == body:
                return True
            b = int(model.body_parentid[b])
        return False

    return frozenset(g for g in range(model.ngeom) if below(int(model.geom_bodyid[g])))
