"""Scenario files (YAML): parsing, validation and the frozen configuration they become.

Every problem is reported as a :class:`ScenarioError` naming the file and the dotted
key (``plant.mass``, ``obstacles[2].polygon``), so the orchestrator can print it and
exit with code 2 before anything starts.  The schema is docs/scenarios.md.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import yaml

from rrtq_sim.disturbance import DisturbanceGenerator, DisturbanceModel
from rrtq_sim.obstacles import as_polygon, load_otte, point_polygon_distance, polygon_from_circle
from rrtq_sim.plant import Plant, rover_matrices
from rrtq_sim.riccati import RiccatiEscape, RiccatiSolution, game_gamma_bound, solve_riccati

__all__ = [
    'ScenarioError',
    'SpringAnchor',
    'PlantModel',
    'ControllerVariant',
    'ObstacleSpec',
    'PlantConfig',
    'DisturbanceConfig',
    'ControllerConfig',
    'Scenario',
    'load_scenario',
    'parse_scenario',
    'build_plant',
    'game_riccati',
    'build_disturbance',
]


class ScenarioError(Exception):
    """A scenario file is unusable.

    Attributes
    ----------
    file : str
        The scenario file.
    key : str
        Dotted path of the offending key ('' for the file as a whole).
    message : str
        What is wrong.
    """

    def __init__(self, file: str, key: str, message: str) -> None:
        super().__init__(file, key, message)
        self.file = file
        self.key = key
        self.message = message

    def __str__(self) -> str:
        return f'{self.file}: {self.key}: {self.message}'


class SpringAnchor(enum.StrEnum):
    """Where the rover's spring is anchored (docs/design.md, Plant)."""

    LEG_TARGET = 'leg_target'
    WORLD_ORIGIN = 'world_origin'


class PlantModel(enum.StrEnum):
    """Plant family."""

    ROVER = 'rover'
    LTI = 'lti'


class ControllerVariant(enum.StrEnum):
    """Controller variant (StrEnum: compares equal to its YAML string)."""

    NOMINAL = 'nominal'
    ROBUST = 'robust'
    OPEN_LOOP = 'open_loop'


@dataclass(frozen=True, eq=False)
class ObstacleSpec:
    """One ground-truth obstacle.

    Attributes
    ----------
    id : str
        Unique name.
    polygon : numpy.ndarray, shape (k, 2)
        Vertices, m (circles arrive as circumscribing polygons).
    appear_at : float
        Time it starts to physically exist, s.
    vanish_at : float
        Time it stops existing, s (``inf``: never; ``== appear_at``: never exists).
    known : bool
        In the robot's map at t = 0.
    """

    id: str
    polygon: np.ndarray
    appear_at: float = 0.0
    vanish_at: float = math.inf
    known: bool = False

    def exists(self, t: float) -> bool:
        """True when it physically exists at ``t`` (s): ``appear_at <= t < vanish_at``."""
        return self.appear_at <= t < self.vanish_at

    @property
    def ever_exists(self) -> bool:
        """True when it physically exists at some time."""
        return self.appear_at < self.vanish_at


@dataclass(frozen=True, eq=False)
class PlantConfig:
    """The simulated plant (the simulator's secret).

    Attributes
    ----------
    model : PlantModel
        ``rover`` or ``lti``.
    A : numpy.ndarray, shape (n, n)
        State matrix, 1/s and 1/s^2 entries (rover: from :func:`rover_matrices`).
    B : numpy.ndarray, shape (n, m)
        Input matrix, 1/kg for the rover.
    mass : float
        kg (rover; nan for lti).
    stiffness : float
        N/m (rover; nan for lti).
    damping : float
        kg/s (rover; nan for lti).
    spring_anchor : SpringAnchor
        Where x_bar is measured from.
    force_limit : float
        Saturation per axis, N.
    """

    model: PlantModel
    A: np.ndarray
    B: np.ndarray
    mass: float
    stiffness: float
    damping: float
    spring_anchor: SpringAnchor
    force_limit: float

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        """Input dimension."""
        return int(self.B.shape[1])


@dataclass(frozen=True, eq=False)
class DisturbanceConfig:
    """The disturbance d(t) applied through F.

    Attributes
    ----------
    model : DisturbanceModel
        Signal kind.
    F : numpy.ndarray, shape (n, q)
        Disturbance matrix.
    amplitude : float
        constant: value; sinusoid: amplitude; gaussian: std; worst_case: clip (units of d).
    frequency : float
        Sinusoid frequency, Hz.
    gamma : float or None
        worst_case: attenuation level of the game that defines d*.
    """

    model: DisturbanceModel
    F: np.ndarray
    amplitude: float
    frequency: float
    gamma: float | None

    @property
    def q(self) -> int:
        """Disturbance dimension."""
        return int(self.F.shape[1])


@dataclass(frozen=True, eq=False)
class ControllerConfig:
    """Controller settings.

    Attributes
    ----------
    variant : ControllerVariant
        ``nominal``, ``robust`` or ``open_loop``.
    horizon : float
        T, the finite horizon per leg, s.
    dt : float
        Delta t, the control and integration step, s.
    M : numpy.ndarray, shape (n, n)
        State weight.
    R : numpy.ndarray, shape (m, m)
        Control weight.
    P_T : numpy.ndarray, shape (n, n)
        Terminal weight.
    alpha_c, alpha_a, alpha_d : float or None
        Critic, actor and disturbance-actor gains; None: chosen from the stability bounds.
    gamma : float or None
        Attenuation level (robust variant).
    rho : float
        Admissible-window radius for the terminal-state evaluation, in units of x_bar.
    forces : tuple of (float, float, float)
        open_loop profile ``(t [s], f_x [N], f_y [N])``, piecewise constant from each t.
    critic_law : str
        ``least_squares`` (default) or ``gradient`` (the papers' normalised gradient law).
    actor_law : str
        ``whitened`` (default) or ``gradient`` (the papers' law).
    initial_gain : numpy.ndarray, shape (m, n), or None
        Initial actor gain K0 (u = -K0 x_bar): an admissible policy to start from, N per
        state unit; None: zero (admissible only when the plant is stable by itself).
    probing_std : float or None
        Probing-noise standard deviation on the first leg, N (None: the core's default).
    probing_decay : float or None
        Factor applied to the probing standard deviation after each leg, in (0, 1].
    """

    variant: ControllerVariant
    horizon: float
    dt: float
    M: np.ndarray
    R: np.ndarray
    P_T: np.ndarray
    alpha_c: float | None
    alpha_a: float | None
    alpha_d: float | None
    gamma: float | None
    rho: float
    forces: tuple[tuple[float, float, float], ...]
    critic_law: str = 'least_squares'
    actor_law: str = 'whitened'
    initial_gain: np.ndarray | None = None
    probing_std: float | None = None
    probing_decay: float | None = None


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated scenario.

    Attributes
    ----------
    path : str
        The file it came from.
    name : str
        Run name (default: the file stem).
    seed : int
        Seed of every random generator in the run.
    bounds : ((float, float), (float, float))
        ((x_min, x_max), (y_min, y_max)), m.
    start, goal : numpy.ndarray, shape (2,)
        Positions, m; the robot starts at rest.
    duration : float
        Simulated time before the run is declared failed, s.
    perception_radius : float
        m.
    robot_radius : float
        m; every obstacle is grown by it.
    plant : PlantConfig
    disturbance : DisturbanceConfig
    controller : ControllerConfig
    planner : dict
        Free-form planner settings.
    obstacles : tuple of ObstacleSpec
        Ground truth, in file order.
    appear_clearance : float
        m; an obstacle due to appear during the run while it is within this distance of
        the robot's disc is held back until it is not
        (:class:`rrtq_sim.perception.TrueObstacles`).
    """

    path: str
    name: str
    seed: int
    bounds: tuple[tuple[float, float], tuple[float, float]]
    start: np.ndarray
    goal: np.ndarray
    duration: float
    perception_radius: float
    robot_radius: float
    plant: PlantConfig
    disturbance: DisturbanceConfig
    controller: ControllerConfig
    planner: dict[str, Any]
    obstacles: tuple[ObstacleSpec, ...]
    appear_clearance: float = 1.0


# --------------------------------------------------------------------------- reading

_TOP_KEYS = (
    'name', 'seed', 'bounds', 'start', 'goal', 'duration', 'perception_radius',
    'robot_radius', 'appear_clearance', 'plant', 'disturbance', 'controller', 'planner',
    'obstacles',
)  # fmt: skip
_ROVER_KEYS = ('model', 'mass', 'stiffness', 'damping', 'spring_anchor', 'force_limit')
_LTI_KEYS = ('model', 'A', 'B', 'spring_anchor', 'force_limit')
_DIST_KEYS = ('model', 'F', 'amplitude', 'frequency', 'gamma')
_CTRL_KEYS = (
    'variant', 'horizon', 'dt', 'M', 'R', 'P_T', 'alpha_c', 'alpha_a', 'alpha_d', 'gamma', 'rho',
    'forces', 'critic_law', 'actor_law', 'initial_gain', 'probing_std', 'probing_decay',
)  # fmt: skip
_TIMING_KEYS = ('appear_at', 'vanish_at', 'known')
_DEFAULT_F4 = np.array([[0.0], [0.0], [-1.0], [1.0]])


def _join(parent: str, child: str) -> str:
    return f'{parent}.{child}' if parent else child


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


class _Reader:
    """Typed access to the parsed YAML, raising ScenarioError with the key path."""

    def __init__(self, file: str) -> None:
        self.file = file

    def error(self, key: str, message: str) -> ScenarioError:
        return ScenarioError(self.file, key, message)

    def mapping(self, value: Any, key: str, allowed: tuple[str, ...] | None) -> dict[Any, Any]:
        """A mapping whose keys are all in ``allowed`` (None: any keys)."""
        if not isinstance(value, Mapping):
            raise self.error(key, f'expected a mapping, got {type(value).__name__}')
        for k in value if allowed is not None else ():
            if k not in allowed:
                allowed_list = ', '.join(allowed)
                raise self.error(_join(key, str(k)), f'unknown key (allowed: {allowed_list})')
        return dict(value)

    def number(
        self,
        value: Any,
        key: str,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        allow_inf: bool = False,
    ) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            hint = ''
            if isinstance(value, str):
                hint = ' (YAML 1.1 reads 1e3 as a string: write 1.0e3)'
            raise self.error(key, f'expected a number, got {type(value).__name__} {value!r}{hint}')
        x = float(value)
        if math.isnan(x) or (math.isinf(x) and not (allow_inf and x > 0)):
            raise self.error(key, f'must be finite, got {x}')
        if positive and not x > 0.0:
            raise self.error(key, f'must be > 0, got {x}')
        if nonnegative and not x >= 0.0:
            raise self.error(key, f'must be >= 0, got {x}')
        return x

    def optional_positive(self, data: Mapping[str, Any], name: str, key: str) -> float | None:
        if data.get(name) is None:
            return None
        return self.number(data[name], _join(key, name), positive=True)

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(key, f'expected true or false, got {value!r}')
        return value

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(key, f'expected a non-empty string, got {value!r}')
        return value

    def choice(self, value: Any, key: str, enum_type: type[enum.StrEnum]) -> Any:
        options = [e.value for e in enum_type]
        if not isinstance(value, str) or value not in options:
            raise self.error(key, f"must be one of {', '.join(options)}, got {value!r}")
        return enum_type(value)

    def matrix(self, value: Any, key: str, shape: tuple[int | None, int | None]) -> np.ndarray:
        rows_ok = isinstance(value, list) and all(isinstance(r, list) and r for r in value)
        if not (rows_ok and value):
            raise self.error(key, 'expected a matrix: a list of rows, each a list of numbers')
        for i, row in enumerate(value):
            if len(row) != len(value[0]):
                raise self.error(key, f'row {i} has {len(row)} entries, row 0 has {len(value[0])}')
            for j, v in enumerate(row):
                self.number(v, f'{key}[{i}][{j}]')
        mat = np.array(value, dtype=float)
        want = tuple(s if s is not None else mat.shape[i] for i, s in enumerate(shape))
        if mat.shape != want:
            got = f'{mat.shape[0]}x{mat.shape[1]}'
            raise self.error(key, f'expected shape {want[0]}x{want[1]}, got {got}')
        return mat

    def weight(self, value: Any, key: str, size: int, *, definite: bool) -> np.ndarray:
        """A weight matrix: a scalar (times identity) or a full symmetric matrix."""
        if isinstance(value, list):
            mat = self.matrix(value, key, (size, size))
        else:
            mat = self.number(value, key, positive=definite, nonnegative=True) * np.eye(size)
        scale = max(1.0, float(np.abs(mat).max()))
        if not np.allclose(mat, mat.T, rtol=0.0, atol=1e-9 * scale):
            raise self.error(key, 'must be symmetric')
        low = float(np.linalg.eigvalsh(mat).min())
        if definite and not low > 1e-12 * scale:
            raise self.error(key, f'must be positive definite (smallest eigenvalue {low:.3g})')
        if not definite and low < -1e-12 * scale:
            raise self.error(key, f'must be positive semi-definite (lowest eigenvalue {low:.3g})')
        return mat

    def point(self, value: Any, key: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) != 2:
            raise self.error(key, f'expected a point [x, y], got {value!r}')
        return np.array([self.number(v, f'{key}[{i}]') for i, v in enumerate(value)])

    def polygon(self, value: Any, key: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) < 3:
            raise self.error(key, 'expected a list of at least 3 vertices [x, y]')
        poly = np.array([self.point(v, f'{key}[{i}]') for i, v in enumerate(value)])
        try:
            return as_polygon(poly)
        except ValueError as exc:
            raise self.error(key, str(exc)) from None


# ---------------------------------------------------------------------- sections


def _plant(r: _Reader, raw: Any) -> PlantConfig:
    key = 'plant'
    data = r.mapping({} if raw is None else raw, key, None)
    model = r.choice(data.get('model', 'rover'), 'plant.model', PlantModel)
    data = r.mapping(data, key, _ROVER_KEYS if model is PlantModel.ROVER else _LTI_KEYS)
    anchor = r.choice(data.get('spring_anchor', 'leg_target'), 'plant.spring_anchor', SpringAnchor)
    limit = r.number(
        data.get('force_limit', 1000.0), 'plant.force_limit', positive=True, allow_inf=True
    )
    if model is PlantModel.ROVER:
        mass = r.number(data.get('mass', 40.0), 'plant.mass', positive=True)
        stiffness = r.number(data.get('stiffness', 20.0), 'plant.stiffness', nonnegative=True)
        damping = r.number(data.get('damping', 45.0), 'plant.damping', nonnegative=True)
        a, b = rover_matrices(mass, stiffness, damping)
    else:
        for name in ('A', 'B'):
            if name not in data:
                raise r.error(f'plant.{name}', 'required for model lti')
        a = r.matrix(data['A'], 'plant.A', (None, None))
        if a.shape[0] != a.shape[1] or a.shape[0] < 2:
            raise r.error(
                'plant.A', f'must be n x n with n >= 2 (states 0, 1: position), got {a.shape}'
            )
        b = r.matrix(data['B'], 'plant.B', (a.shape[0], None))
        mass = stiffness = damping = math.nan
    return PlantConfig(model, _frozen(a), _frozen(b), mass, stiffness, damping, anchor, limit)


def _disturbance(r: _Reader, raw: Any, n: int, needs_f: bool) -> DisturbanceConfig:
    data = r.mapping({} if raw is None else raw, 'disturbance', _DIST_KEYS)
    model = r.choice(data.get('model', 'none'), 'disturbance.model', DisturbanceModel)
    if 'F' in data:
        f = r.matrix(data['F'], 'disturbance.F', (n, None))
    elif n == 4:
        f = _DEFAULT_F4
    elif model is DisturbanceModel.NONE and not needs_f:
        f = np.zeros((n, 1))
    else:
        raise r.error('disturbance.F', f'required when the plant has n = {n} != 4 states')
    signed = model in (DisturbanceModel.CONSTANT, DisturbanceModel.SINUSOID)
    amplitude = r.number(
        data.get('amplitude', 1.0), 'disturbance.amplitude', nonnegative=not signed
    )
    frequency = r.number(data.get('frequency', 0.2), 'disturbance.frequency', nonnegative=True)
    gamma = r.optional_positive(data, 'gamma', 'disturbance')
    if model is DisturbanceModel.WORST_CASE and gamma is None:
        raise r.error('disturbance.gamma', 'required for model worst_case')
    return DisturbanceConfig(model, _frozen(f), amplitude, frequency, gamma)


def _forces(r: _Reader, raw: Any, key: str) -> tuple[tuple[float, float, float], ...]:
    if not isinstance(raw, list) or not raw:
        raise r.error(key, 'expected a non-empty list of [t, fx, fy]')
    out: list[tuple[float, float, float]] = []
    for i, row in enumerate(raw):
        k = f'{key}[{i}]'
        if not isinstance(row, list) or len(row) != 3:
            raise r.error(k, f'expected [t, fx, fy], got {row!r}')
        t = r.number(row[0], f'{k}[0]', nonnegative=True)
        if out and not t > out[-1][0]:
            raise r.error(k, f'times must be strictly increasing ({t} after {out[-1][0]})')
        out.append((t, r.number(row[1], f'{k}[1]'), r.number(row[2], f'{k}[2]')))
    return tuple(out)


def _controller(r: _Reader, raw: Any, n: int, m: int) -> ControllerConfig:
    data = r.mapping({} if raw is None else raw, 'controller', _CTRL_KEYS)
    variant = r.choice(data.get('variant', 'nominal'), 'controller.variant', ControllerVariant)
    horizon = r.number(data.get('horizon', 10.0), 'controller.horizon', positive=True)
    dt = r.number(data.get('dt', 0.05), 'controller.dt', positive=True)
    if dt > horizon:
        raise r.error('controller.dt', f'dt = {dt} s exceeds the horizon {horizon} s')
    weights = {
        'M': r.weight(data.get('M', 10.0), 'controller.M', n, definite=False),
        'R': r.weight(data.get('R', 2.0), 'controller.R', m, definite=True),
        'P_T': r.weight(data.get('P_T', 0.5), 'controller.P_T', n, definite=False),
    }
    gamma = r.optional_positive(data, 'gamma', 'controller')
    if variant is ControllerVariant.ROBUST and gamma is None:
        raise r.error('controller.gamma', 'required for the robust variant')
    forces: tuple[tuple[float, float, float], ...] = ()
    if variant is ControllerVariant.OPEN_LOOP:
        if 'forces' not in data:
            raise r.error('controller.forces', 'required for the open_loop variant')
        if m != 2:
            raise r.error(
                'controller.forces', f'[t, fx, fy] needs a plant with 2 inputs, this one has {m}'
            )
        forces = _forces(r, data['forces'], 'controller.forces')
    elif 'forces' in data:
        raise r.error('controller.forces', f'only for the open_loop variant, not {variant}')
    return ControllerConfig(
        variant=variant,
        horizon=horizon,
        dt=dt,
        M=_frozen(weights['M']),
        R=_frozen(weights['R']),
        P_T=_frozen(weights['P_T']),
        alpha_c=r.optional_positive(data, 'alpha_c', 'controller'),
        alpha_a=r.optional_positive(data, 'alpha_a', 'controller'),
        alpha_d=r.optional_positive(data, 'alpha_d', 'controller'),
        gamma=gamma,
        rho=r.number(data.get('rho', 0.15), 'controller.rho', positive=True),
        forces=forces,
        critic_law=_one_of(r, data.get('critic_law', 'least_squares'), 'controller.critic_law',
                           ('least_squares', 'gradient')),
        actor_law=_one_of(r, data.get('actor_law', 'whitened'), 'controller.actor_law',
                          ('whitened', 'gradient')),
        initial_gain=(None if data.get('initial_gain') is None else _frozen(
            r.matrix(data['initial_gain'], 'controller.initial_gain', (m, n)))),
        probing_std=(None if 'probing_std' not in data else r.number(
            data['probing_std'], 'controller.probing_std', nonnegative=True)),
        probing_decay=(None if 'probing_decay' not in data else _fraction(
            r, data['probing_decay'], 'controller.probing_decay')),
    )


# planner key -> (default, lowest value, integer?)
PLANNER_KEYS: dict[str, tuple[float, float, bool]] = {
    'steer_distance': (5.0, 1e-3, False),       # m, RRT^X delta
    'epsilon': (0.0, 0.0, False),               # m, epsilon-consistency
    'iterations_per_step': (30, 0, True),       # lock-step sampling budget per step
    'max_nodes': (3000, 2, True),               # past this size the graph only fills gaps
    'cycle_budget_ms': (10.0, 0.1, False),      # paced: wall time of sampling per cycle
    'tree_period_s': (1.0, 0.0, False),         # sim time between /planner/tree messages
    'goal_tolerance': (0.5, 1e-3, False),       # m, distance that counts as arrived
    'growth_threshold': (0.05, 0.0, False),     # m, margin growth that republishes
}


def _planner(r: _Reader, raw: Any) -> dict[str, Any]:
    data = r.mapping({} if raw is None else raw, 'planner', tuple(PLANNER_KEYS))
    out: dict[str, Any] = {}
    for key, (default, low, integer) in PLANNER_KEYS.items():
        value = r.number(data.get(key, default), f'planner.{key}', nonnegative=True)
        if value < low or (integer and value != int(value)):
            kind = 'an integer' if integer else 'a number'
            raise r.error(f'planner.{key}', f'must be {kind} >= {low}, got {value}')
        out[key] = int(value) if integer else value
    return out


def _one_of(r: _Reader, value: Any, key: str, allowed: tuple[str, ...]) -> str:
    text = r.string(value, key)
    if text not in allowed:
        raise r.error(key, f'{text!r} is not one of {", ".join(allowed)}')
    return text


def _fraction(r: _Reader, value: Any, key: str) -> float:
    number = r.number(value, key, positive=True)
    if number > 1.0:
        raise r.error(key, f'must be in (0, 1], got {number}')
    return number


def _timing(r: _Reader, data: Mapping[str, Any], key: str) -> tuple[float, float, bool]:
    appear = r.number(data.get('appear_at', 0.0), _join(key, 'appear_at'), nonnegative=True)
    vanish = r.number(
        data.get('vanish_at', math.inf), _join(key, 'vanish_at'), nonnegative=True, allow_inf=True
    )
    # appear_at == vanish_at is allowed: an obstacle that never exists but may be
    # believed (known: true, vanish_at: 0 in the example of docs/design.md; Otte flag -1).
    if appear > vanish:
        raise r.error(
            _join(key, 'vanish_at'), f'vanish_at = {vanish} is before appear_at = {appear}'
        )
    known = r.boolean(data.get('known', False), _join(key, 'known'))
    return appear, vanish, known


def _obstacle_file(
    r: _Reader, data: dict[str, Any], key: str, base_dir: str
) -> list[ObstacleSpec]:
    fmt = data.get('format', 'otte')
    if fmt != 'otte':
        raise r.error(_join(key, 'format'), f"only 'otte' is supported, got {fmt!r}")
    rel = r.string(data['file'], _join(key, 'file'))
    path = rel if os.path.isabs(rel) else os.path.join(base_dir, rel)
    discoverable = r.boolean(data.get('discoverable', False), _join(key, 'discoverable'))
    if discoverable:
        for name in _TIMING_KEYS:
            if name in data:
                raise r.error(
                    _join(key, name), "set by the file's flags when discoverable is true"
                )
    try:
        entries = load_otte(path)
    except OSError as exc:
        raise r.error(_join(key, 'file'), f'cannot read {path}: {exc.strerror or exc}') from None
    except ValueError as exc:
        raise r.error(_join(key, 'file'), str(exc)) from None
    stem = os.path.splitext(os.path.basename(path))[0]
    appear, vanish, known = _timing(r, data, key)
    specs = []
    for i, (poly, flag) in enumerate(entries):
        if discoverable:
            if flag is None:
                raise r.error(_join(key, 'discoverable'), f'{path} has no flag lines')
            # Otte: 0 static and known; 1 unknown until sensed; -1 believed but absent.
            appear, vanish, known = 0.0, (0.0 if flag == -1 else math.inf), flag != 1
        specs.append(ObstacleSpec(f'{stem}_{i}', _frozen(poly), appear, vanish, known))
    return specs


def _obstacles(r: _Reader, raw: Any, base_dir: str) -> tuple[ObstacleSpec, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise r.error('obstacles', f'expected a list, got {type(raw).__name__}')
    specs: list[ObstacleSpec] = []
    seen: set[str] = set()
    for i, entry in enumerate(raw):
        key = f'obstacles[{i}]'
        if not isinstance(entry, Mapping):
            raise r.error(key, f'expected a mapping, got {type(entry).__name__}')
        shapes = [s for s in ('polygon', 'circle', 'file') if s in entry]
        if len(shapes) != 1:
            raise r.error(key, 'needs exactly one of polygon, circle, file')
        if shapes[0] == 'file':
            data = r.mapping(entry, key, ('file', 'format', 'discoverable') + _TIMING_KEYS)
            new = _obstacle_file(r, data, key, base_dir)
        else:
            data = r.mapping(entry, key, ('id', shapes[0]) + _TIMING_KEYS)
            if 'id' not in data:
                raise r.error(_join(key, 'id'), 'required')
            ident = r.string(data['id'], _join(key, 'id'))
            if shapes[0] == 'polygon':
                poly = r.polygon(data['polygon'], _join(key, 'polygon'))
            else:
                ck = _join(key, 'circle')
                circle = r.mapping(data['circle'], ck, ('center', 'radius'))
                for name in ('center', 'radius'):
                    if name not in circle:
                        raise r.error(_join(ck, name), 'required')
                center = r.point(circle['center'], _join(ck, 'center'))
                radius = r.number(circle['radius'], _join(ck, 'radius'), positive=True)
                poly = polygon_from_circle(center, radius)
            new = [ObstacleSpec(ident, _frozen(poly), *_timing(r, data, key))]
        for spec in new:
            if spec.id in seen:
                where = _join(key, 'file' if shapes[0] == 'file' else 'id')
                raise r.error(where, f'duplicate id {spec.id!r}')
            seen.add(spec.id)
        specs.extend(new)
    return tuple(specs)


def _bounds(r: _Reader, raw: Any) -> tuple[tuple[float, float], tuple[float, float]]:
    data = r.mapping(raw, 'bounds', ('x', 'y'))
    out = []
    for axis in ('x', 'y'):
        key = f'bounds.{axis}'
        if axis not in data:
            raise r.error(key, 'required')
        lo, hi = r.point(data[axis], key)
        if not lo < hi:
            raise r.error(key, f'expected [min, max] with min < max, got [{lo}, {hi}]')
        out.append((float(lo), float(hi)))
    return out[0], out[1]


def _check_game(
    r: _Reader, key: str, plant: PlantConfig, ctrl: ControllerConfig, f: np.ndarray, gamma: float
) -> None:
    """Reject a gamma below the finite-horizon game bound: no saddle point exists."""
    try:
        solve_riccati(plant.A, plant.B, ctrl.M, ctrl.R, ctrl.P_T, ctrl.horizon, f, gamma)
    except RiccatiEscape as exc:
        # Coarse: the bound only has to tell the user roughly where to go.
        bound = game_gamma_bound(
            plant.A, plant.B, ctrl.M, ctrl.R, ctrl.P_T, ctrl.horizon, f, tol=0.02
        )
        raise r.error(
            key, f'gamma = {gamma} is below the game bound (about {bound:.3g}) ({exc})'
        ) from None


def parse_scenario(data: Any, path: str) -> Scenario:
    """Validate parsed YAML and build a :class:`Scenario`.

    Parameters
    ----------
    data : dict
        The parsed document.
    path : str
        The file it came from: named in errors, and the base for relative obstacle files.

    Raises
    ------
    ScenarioError
    """
    r = _Reader(path)
    if not isinstance(data, Mapping):
        raise r.error('', f'the top level must be a mapping, got {type(data).__name__}')
    data = r.mapping(data, '', _TOP_KEYS)
    for name in ('bounds', 'start', 'goal'):
        if name not in data:
            raise r.error(name, 'required')
    stem = os.path.splitext(os.path.basename(path))[0] or 'scenario'
    name = r.string(data.get('name', stem), 'name')
    seed_raw = data.get('seed', 0)
    if isinstance(seed_raw, bool) or not isinstance(seed_raw, int) or seed_raw < 0:
        raise r.error('seed', f'expected an integer >= 0, got {seed_raw!r}')
    bounds = _bounds(r, data['bounds'])
    start = r.point(data['start'], 'start')
    goal = r.point(data['goal'], 'goal')
    duration = r.number(data.get('duration', 300.0), 'duration', positive=True)
    perception_radius = r.number(
        data.get('perception_radius', 8.0), 'perception_radius', positive=True
    )
    robot_radius = r.number(data.get('robot_radius', 0.0), 'robot_radius', nonnegative=True)
    appear_clearance = r.number(
        data.get('appear_clearance', 1.0), 'appear_clearance', nonnegative=True
    )
    plant = _plant(r, data.get('plant'))
    ctrl_raw = data.get('controller')
    robust = isinstance(ctrl_raw, Mapping) and ctrl_raw.get('variant') == 'robust'
    disturbance = _disturbance(r, data.get('disturbance'), plant.n, robust)
    controller = _controller(r, ctrl_raw, plant.n, plant.m)
    planner = _planner(r, data.get('planner'))
    obstacles = _obstacles(r, data.get('obstacles'), os.path.dirname(os.path.abspath(path)))

    for key, p in (('start', start), ('goal', goal)):
        (x0, x1), (y0, y1) = bounds
        if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            raise r.error(key, f'{p.tolist()} is outside the bounds x {[x0, x1]}, y {[y0, y1]}')
    for spec in obstacles:
        dist = float(point_polygon_distance(start, spec.polygon))
        blocked = dist <= 0.0 or dist < robot_radius
        if blocked and spec.exists(0.0):
            raise r.error('start', f'{start.tolist()} is inside obstacle {spec.id!r} at t = 0')
        dist = float(point_polygon_distance(goal, spec.polygon))
        if (dist <= 0.0 or dist < robot_radius) and spec.ever_exists:
            raise r.error('goal', f'{goal.tolist()} is inside obstacle {spec.id!r}')

    if disturbance.model is DisturbanceModel.WORST_CASE:
        assert disturbance.gamma is not None
        _check_game(r, 'disturbance.gamma', plant, controller, disturbance.F, disturbance.gamma)
    if controller.variant is ControllerVariant.ROBUST:
        assert controller.gamma is not None
        _check_game(r, 'controller.gamma', plant, controller, disturbance.F, controller.gamma)

    return Scenario(
        path=path,
        name=name,
        seed=seed_raw,
        bounds=bounds,
        start=_frozen(start),
        goal=_frozen(goal),
        duration=duration,
        perception_radius=perception_radius,
        robot_radius=robot_radius,
        plant=plant,
        disturbance=disturbance,
        controller=controller,
        planner=dict(planner),
        obstacles=obstacles,
        appear_clearance=appear_clearance,
    )


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that rejects duplicate mapping keys (PyYAML keeps the last silently)."""


def _construct_mapping(loader: _StrictLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    loader.flatten_mapping(node)
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            duplicate = key in seen
            seen.add(key)
        except TypeError:
            continue  # unhashable key: construct_mapping reports it
        if duplicate:
            raise yaml.constructor.ConstructorError(
                None, None, f'duplicate key {key!r}', key_node.start_mark
            )
    return loader.construct_mapping(node, deep=True)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def load_scenario(path: str | os.PathLike[str], seed: int | None = None) -> Scenario:
    """Read, validate and build a scenario file.

    Parameters
    ----------
    path : str or path-like
    seed : int, optional
        Overrides the file's seed (``rrtq run --seed``).

    Raises
    ------
    ScenarioError
        With key '' for an unreadable file, a YAML error or a non-mapping document.
    """
    file = os.fspath(path)
    try:
        with open(file, encoding='utf-8') as fh:
            data = yaml.load(fh, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except OSError as exc:
        raise ScenarioError(file, '', f'cannot read the file: {exc.strerror or exc}') from None
    except yaml.YAMLError as exc:
        raise ScenarioError(file, '', f'YAML error: {exc}') from None
    scenario = parse_scenario(data, file)
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ScenarioError(
                file, 'seed', f'the seed override must be an integer >= 0, got {seed!r}'
            )
        scenario = dataclasses.replace(scenario, seed=seed)
    return scenario


# ---------------------------------------------------------------------- builders


def build_plant(scenario: Scenario) -> Plant:
    """The simulator's plant: true matrices, F, the controller's dt, the force limit."""
    p = scenario.plant
    return Plant(p.A, p.B, scenario.disturbance.F, scenario.controller.dt, p.force_limit)


def game_riccati(scenario: Scenario, gamma: float) -> RiccatiSolution:
    """Game Riccati solution over one leg (horizon T): controller weights, true plant."""
    p, c = scenario.plant, scenario.controller
    return solve_riccati(p.A, p.B, c.M, c.R, c.P_T, c.horizon, scenario.disturbance.F, gamma)


def build_disturbance(scenario: Scenario, rng: np.random.Generator) -> DisturbanceGenerator:
    """The disturbance injector's generator (worst_case: the game at ``disturbance.gamma``)."""
    d = scenario.disturbance
    riccati = None
    if d.model is DisturbanceModel.WORST_CASE:
        assert d.gamma is not None
        riccati = game_riccati(scenario, d.gamma)
    return DisturbanceGenerator(d.model, d.q, d.amplitude, d.frequency, rng, riccati, d.F, d.gamma)
