"""The guiding level as one object: desired path + augmented obstacles -> reference trajectory.

:class:`GuidanceTrack` rolls the integral curve (eq. 17) out once from the robot to the
goal, and at each control step cuts from it the reference the controller tracks: from
the curve point nearest the robot (searched forward only, so the reference never runs
backwards), re-profiled from the robot's own speed, sampled every ``dt`` over the
horizon. When the robot has left the curve by more than half the reactive width, the
curve is rolled out again from where the robot is: the field is defined everywhere, so
the new curve joins the path from there. A curve rolled out from a moving robot starts
along its velocity and turns onto the field no harder than its speed allows (the
connector of :func:`integral_curve`), so a rebuilt track is continuous in heading and
speed with the robot's motion.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from .config import CurveStatus, GuidanceConfig
from .curve import Curve, Reference, integral_curve, sample_in_time, speed_profile
from .field import CompositeField, place_virtual_obstacles
from .obstacles import PolygonDistances
from .path import FilletedPath

__all__ = ['GuidanceTrack']


class GuidanceTrack:
    """Reference trajectories along the kinodynamic composite field of one path.

    Parameters
    ----------
    path : array_like, shape (k, 2)
        The desired path (the RRT^X path), m, start first.
    obstacles : sequence of array_like
        The augmented obstacles' polygons, m.
    config : GuidanceConfig
    """

    def __init__(self, path: npt.ArrayLike, obstacles: Sequence[npt.ArrayLike],
                 config: GuidanceConfig) -> None:
        self.config = config
        self.path = FilletedPath(path, config.min_turn_radius)
        self.obstacles = PolygonDistances(obstacles)
        virtual, circulation = place_virtual_obstacles(self.path, self.obstacles, config)
        self.field = CompositeField(self.path, self.obstacles, config, virtual, circulation)
        self.curve: Curve | None = None
        self._index = 0
        self.rollouts = 0

    def roll(self, start: npt.ArrayLike, velocity: npt.ArrayLike | None = None) -> Curve:
        """The integral curve from ``start`` to the goal (or until it stalls).

        With the robot's ``velocity``, it leaves ``start`` along it and turns onto the
        field within the acceleration limit (:func:`integral_curve`'s connector).
        """
        budget = 3.0 * self.path.length + 50.0
        self.curve = integral_curve(self.field, start, budget, velocity=velocity)
        self._index = 0
        self.rollouts += 1
        return self.curve

    def reference(self, position: npt.ArrayLike, velocity: npt.ArrayLike,
                  t0: float = 0.0) -> Reference:
        """The reference from the robot's state: ``horizon/dt + 1`` samples from ``t0``."""
        cfg = self.config
        p = np.asarray(position, dtype=float).reshape(2)
        v = np.asarray(velocity, dtype=float).reshape(2)
        if self.curve is None:
            self.roll(p, v)
        assert self.curve is not None
        pts = self.curve.points
        lo = max(self._index - 10, 0)
        hi = min(self._index + 400, len(pts))
        dist = np.hypot(*(pts[lo:hi] - p).T)
        k = lo + int(np.argmin(dist))
        if float(dist[k - lo]) > 0.5 * cfg.reactive_width:
            pts = self.roll(p, v).points
            k = 0
        self._index = k
        reach = cfg.v_max * cfg.horizon + cfg.v_max ** 2 / cfg.a_max + 2.0 * cfg.step
        end = min(len(pts), k + int(math.ceil(reach / cfg.step)) + 2)
        window = pts[k:end]
        if len(window) < 2:
            window = np.vstack((pts[-1], pts[-1]))
        tangent = window[min(1, len(window) - 1)] - window[0]
        norm = float(np.hypot(*tangent))
        v_along = float(v @ tangent) / norm if norm > 0.0 else 0.0
        last = end == len(pts) and self.curve.status is CurveStatus.REACHED
        speeds = speed_profile(window, cfg, v_along, stop_at_end=last)
        count = int(round(cfg.horizon / cfg.dt)) + 1
        return sample_in_time(window, speeds, cfg.dt, count, t0)

    @property
    def status(self) -> CurveStatus | None:
        """How the last rollout ended."""
        return None if self.curve is None else self.curve.status
