"""Linear plant with force saturation, integrated exactly under a zero-order hold.

The rover is the mass-spring-damper of the RRT-QX paper (eq. 26): per axis
``m p'' = -k (p - anchor) - c p' + u``.  Any other linear plant (``lti``) uses the
same machinery; its first two state components are taken as the planar position.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.linalg import expm

from rrtq_common.settings import check, setting

__all__ = ['SpringAnchor', 'PlantModel', 'PlantConfig', 'rover_matrices', 'Plant']


class SpringAnchor(enum.StrEnum):
    """Where the rover's spring is anchored (docs/design.md, Plant)."""

    LEG_TARGET = 'leg_target'
    WORLD_ORIGIN = 'world_origin'


class PlantModel(enum.StrEnum):
    """Plant family."""

    ROVER = 'rover'
    LTI = 'lti'
    MUJOCO = 'mujoco'
    """The physics plant (:mod:`rrtq_sim.mujoco_plant`); A and B are its free-motion rover."""


@dataclass(frozen=True, eq=False, kw_only=True)
class PlantConfig:
    """The simulated plant (the simulator's secret).

    The rover's matrices follow from its mass, stiffness and damping
    (:func:`rover_matrices`); an ``lti`` plant gives A and B (mass, stiffness and damping
    are then nan). A ``mujoco`` plant is stepped by MuJoCo; its A and B are the rover's
    without spring or friction (its free motion), for what needs a linear model of the
    truth (the worst-case game, the leg tables). With ``mjcf`` its mass is the file's base
    (and what it carries) and damping is nan (the file's own business).
    """

    A: np.ndarray = setting(rows='n', doc='state matrix A (n x n), 1/s and 1/s^2 entries')
    B: np.ndarray = setting(rows='n', doc='input matrix B (n x m), 1/kg for the rover')
    model: PlantModel = setting(PlantModel.ROVER, doc='plant family')
    mass: float = setting(40.0, unit='kg', low=0.0, low_open=True, doc='rover mass m')
    stiffness: float = setting(20.0, unit='N/m', low=0.0, doc='rover spring constant k')
    damping: float = setting(45.0, unit='kg/s', low=0.0, doc='rover viscous damping c')
    spring_anchor: SpringAnchor = setting(SpringAnchor.LEG_TARGET,
                                          doc='where x_bar is measured from')
    force_limit: float = setting(1000.0, unit='N', low=0.0, low_open=True,
                                 doc='saturation per axis (inf: none)')
    actuation_delay: float = setting(0.0, unit='s', low=0.0, doc='the force commanded at a '
                                     'step acts this much later (a multiple of the step)')
    friction: float = setting(0.0, unit='1', low=0.0, doc='mujoco: Coulomb friction '
                              'coefficient mu; per axis the base resists at rest up to '
                              'mu m g (g = 9.81 m/s^2)')
    mjcf: str | None = setting(None, doc='mujoco: a user MJCF file (body base, actuators fx '
                               'and fy); none: the shipped planar base')

    def __post_init__(self) -> None:
        check(self)

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        """Input dimension."""
        return int(self.B.shape[1])


def rover_matrices(mass: float, stiffness: float, damping: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the rover's continuous-time ``(A, B)`` (RRT-QX eq. 26).

    Parameters
    ----------
    mass : float
        Mass m, kg (> 0).
    stiffness : float
        Spring constant k, N/m (>= 0).
    damping : float
        Viscous damping c, kg/s (>= 0).

    Returns
    -------
    A : numpy.ndarray, shape (4, 4)
        State matrix for x = (p_x, p_y, v_x, v_y).
    B : numpy.ndarray, shape (4, 2)
        Input matrix for u = (f_x, f_y) in N.
    """
    if not (np.isfinite(mass) and mass > 0.0):
        raise ValueError(f'mass must be finite and > 0, got {mass!r}')
    if not (np.isfinite(stiffness) and stiffness >= 0.0):
        raise ValueError(f'stiffness must be finite and >= 0, got {stiffness!r}')
    if not (np.isfinite(damping) and damping >= 0.0):
        raise ValueError(f'damping must be finite and >= 0, got {damping!r}')
    a = np.zeros((4, 4))
    a[0, 2] = a[1, 3] = 1.0
    a[2, 0] = a[3, 1] = -stiffness / mass
    a[2, 2] = a[3, 3] = -damping / mass
    b = np.zeros((4, 2))
    b[2, 0] = b[3, 1] = 1.0 / mass
    return a, b


class Plant:
    """Exact zero-order-hold discretisation of ``x' = A x_bar + B sat(u) + F d``.

    ``x_bar`` is the state relative to the spring anchor: the anchor position is
    subtracted from the first two components.  Because the anchor is constant over a
    step, ``x_bar' = x'`` and the step can be taken in anchor coordinates.

    Parameters
    ----------
    A : array_like, shape (n, n)
        Continuous-time state matrix (n >= 2; components 0 and 1 are the position, m).
    B : array_like, shape (n, m)
        Continuous-time input matrix (u in N).
    F : array_like, shape (n, q), or None
        Disturbance matrix; ``None`` means no disturbance input (q = 0).
    dt : float
        Step length, s (> 0).
    force_limit : float
        Saturation per input axis, N (> 0; ``inf`` disables saturation).
    """

    def __init__(
        self,
        A: npt.ArrayLike,
        B: npt.ArrayLike,
        F: npt.ArrayLike | None,
        dt: float,
        force_limit: float,
    ) -> None:
        a = np.array(A, dtype=float, ndmin=2)
        n = a.shape[0]
        if a.ndim != 2 or a.shape != (n, n) or n < 2:
            raise ValueError(f'A must be square with n >= 2, got shape {a.shape}')
        b = np.array(B, dtype=float, ndmin=2)
        if b.ndim != 2 or b.shape[0] != n or b.shape[1] < 1:
            raise ValueError(f'B must have shape ({n}, m>=1), got {b.shape}')
        f = np.zeros((n, 0)) if F is None else np.array(F, dtype=float, ndmin=2)
        if f.ndim != 2 or f.shape[0] != n:
            raise ValueError(f'F must have shape ({n}, q), got {f.shape}')
        for name, mat in (('A', a), ('B', b), ('F', f)):
            if not np.all(np.isfinite(mat)):
                raise ValueError(f'{name} must be finite')
        if not (np.isfinite(dt) and dt > 0.0):
            raise ValueError(f'dt must be finite and > 0, got {dt!r}')
        if not (force_limit > 0.0):
            raise ValueError(f'force_limit must be > 0, got {force_limit!r}')
        m, q = b.shape[1], f.shape[1]
        # One exponential of the augmented generator gives Phi and both input
        # integrals int_0^dt e^{As} ds (B, F) exactly, with no inversion of A (A may
        # be singular: the spring-free rover is a double integrator).
        aug = np.zeros((n + m + q, n + m + q))
        aug[:n, :n] = a
        aug[:n, n : n + m] = b
        aug[:n, n + m :] = f
        e = expm(aug * dt)
        self._phi = e[:n, :n].copy()
        self._gamma_u = e[:n, n : n + m].copy()
        self._gamma_d = e[:n, n + m :].copy()
        for mat in (self._phi, self._gamma_u, self._gamma_d):
            mat.setflags(write=False)
        self._n, self._m, self._q = n, m, q
        self._dt = float(dt)
        self._force_limit = float(force_limit)

    @property
    def n(self) -> int:
        """State dimension."""
        return self._n

    @property
    def m(self) -> int:
        """Input (force) dimension."""
        return self._m

    @property
    def q(self) -> int:
        """Disturbance dimension."""
        return self._q

    @property
    def dt(self) -> float:
        """Step length, s."""
        return self._dt

    @property
    def force_limit(self) -> float:
        """Saturation per input axis, N."""
        return self._force_limit

    @property
    def phi(self) -> np.ndarray:
        """Discrete state transition e^{A dt}, shape (n, n) (read-only)."""
        return self._phi

    @property
    def gamma_u(self) -> np.ndarray:
        """Discrete input matrix int_0^dt e^{As} ds B, shape (n, m) (read-only)."""
        return self._gamma_u

    @property
    def gamma_d(self) -> np.ndarray:
        """Discrete disturbance matrix int_0^dt e^{As} ds F, shape (n, q) (read-only)."""
        return self._gamma_d

    def saturate(self, u: npt.ArrayLike) -> np.ndarray:
        """Clip each force component to ``[-force_limit, force_limit]``, N.

        Raises
        ------
        ValueError
            If ``u`` has the wrong shape or is not finite: a NaN force is a
            controller bug and must not silently poison the state.
        """
        uu = np.asarray(u, dtype=float).reshape(-1)
        if uu.shape != (self._m,):
            raise ValueError(f'u must have shape ({self._m},), got {np.shape(u)}')
        if not np.all(np.isfinite(uu)):
            raise ValueError(f'u must be finite, got {uu}')
        return np.clip(uu, -self._force_limit, self._force_limit)

    def step(
        self,
        x: npt.ArrayLike,
        u: npt.ArrayLike,
        d: npt.ArrayLike | None,
        anchor: npt.ArrayLike,
    ) -> np.ndarray:
        """Advance the full state by one ``dt`` with ``u`` and ``d`` held constant.

        Parameters
        ----------
        x : array_like, shape (n,)
            Full state (position in the world frame, m; then velocities, m/s).
        u : array_like, shape (m,)
            Commanded force, N; saturated before it is applied.
        d : array_like, shape (q,), or None
            Disturbance; ``None`` means zero.
        anchor : array_like, shape (2,)
            Spring anchor position, m.

        Returns
        -------
        numpy.ndarray, shape (n,)
            The full state after ``dt`` (world frame).
        """
        xx = np.asarray(x, dtype=float).reshape(-1)
        if xx.shape != (self._n,):
            raise ValueError(f'x must have shape ({self._n},), got {np.shape(x)}')
        dd = np.zeros(self._q) if d is None else np.asarray(d, dtype=float).reshape(-1)
        if dd.shape != (self._q,):
            raise ValueError(f'd must have shape ({self._q},), got {np.shape(np.asarray(d))}')
        if not np.all(np.isfinite(dd)):
            raise ValueError(f'd must be finite, got {dd}')
        anc = np.asarray(anchor, dtype=float).reshape(-1)
        if anc.shape != (2,):
            raise ValueError(f'anchor must have shape (2,), got {np.shape(anchor)}')
        offset = np.zeros(self._n)
        offset[:2] = anc
        xbar = xx - offset
        xbar_next = self._phi @ xbar + self._gamma_u @ self.saturate(u) + self._gamma_d @ dd
        return xbar_next + offset
