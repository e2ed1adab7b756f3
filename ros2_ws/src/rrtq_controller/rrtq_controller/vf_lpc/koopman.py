"""Nominal model by EDMD with control (VF-LPC §III-B, eqs. 3-4), fitted from data.

The Koopman operator of ``x_{k+1} = f(x_k, u_k)`` acts linearly on observables; EDMD
with control (Williams et al. 2015; Korda & Mezić 2018) approximates it on a finite
dictionary ``psi``: ``psi(x_{k+1}) ~= A psi(x_k) + B u_k`` by least squares, and reads
the state back as ``x = C psi(x)``. The paper learns ``psi`` with an encoder (deep
Koopman); a lifting here is any callable, with two built in: ``linear`` (``psi(x) = x``,
exact for a linear plant such as the rover) and ``affine`` (``psi(x) = (x, 1)``: a
constant force or a spring to a fixed anchor).
"""

from __future__ import annotations

import pathlib
import zipfile
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ['Lifting', 'LIFTINGS', 'KoopmanModel', 'fit_edmd', 'prediction_errors']


@dataclass(frozen=True)
class Lifting:
    """A dictionary of observables ``psi``: (N, n) states -> (N, p) lifted states.

    The first ``n`` observables must be the state itself, so that ``C = [I 0]``.
    """

    name: str
    psi: Callable[[np.ndarray], np.ndarray]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.psi(np.atleast_2d(np.asarray(x, dtype=float)))


LIFTINGS: dict[str, Lifting] = {
    'linear': Lifting('linear', lambda x: x.copy()),
    'affine': Lifting('affine', lambda x: np.hstack((x, np.ones((x.shape[0], 1))))),
}


@dataclass(frozen=True)
class KoopmanModel:
    """``z_{k+1} = A z_k + B u_k``, ``z = psi(x)``, ``x = C z`` (eq. 4), every ``dt``.

    Attributes
    ----------
    A : numpy.ndarray, shape (p, p)
    B : numpy.ndarray, shape (p, m)
    C : numpy.ndarray, shape (n, p)
    dt : float
        s.
    lifting : Lifting
    force_limit : float
        N per axis the data was saturated at (inf if unknown).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    dt: float
    lifting: Lifting
    force_limit: float = np.inf

    @property
    def n(self) -> int:
        return self.C.shape[0]

    @property
    def m(self) -> int:
        return self.B.shape[1]

    def lift(self, x: npt.ArrayLike) -> np.ndarray:
        """psi(x) for (n,) or (N, n) states."""
        xx = np.asarray(x, dtype=float)
        z = self.lifting(xx)
        return z[0] if xx.ndim == 1 else z

    def step(self, x: npt.ArrayLike, u: npt.ArrayLike) -> np.ndarray:
        """One-step prediction ``C (A psi(x) + B u)`` for (n,) or (N, n) states."""
        xx = np.asarray(x, dtype=float)
        z = self.lifting(xx)
        uu = np.atleast_2d(np.asarray(u, dtype=float))
        out = (z @ self.A.T + uu @ self.B.T) @ self.C.T
        return out[0] if xx.ndim == 1 else out

    def rollout(self, x0: npt.ArrayLike, us: npt.ArrayLike) -> np.ndarray:
        """Open-loop prediction in the lifted space: states (K+1, n) for inputs (K, m)."""
        z = self.lift(x0)
        out = [self.C @ z]
        for u in np.asarray(us, dtype=float):
            z = self.A @ z + self.B @ u
            out.append(self.C @ z)
        return np.array(out)

    def save(self, path: str | pathlib.Path) -> None:
        """Write the model as ``.npz`` (the lifting by name)."""
        np.savez(path, A=self.A, B=self.B, C=self.C, dt=self.dt,
                 lifting=np.array(self.lifting.name), force_limit=self.force_limit)

    @classmethod
    def load(cls, path: str | pathlib.Path, liftings: dict[str, Lifting] | None = None
             ) -> 'KoopmanModel':
        """Read a model written by :meth:`save`; a custom lifting must be passed by name.

        Raises
        ------
        ValueError
            Missing arrays, inconsistent shapes or an unknown lifting (names the file).
        """
        table = {**LIFTINGS, **(liftings or {})}
        try:
            with np.load(path, allow_pickle=False) as data:
                a, b, c = (np.asarray(data[k], dtype=float) for k in ('A', 'B', 'C'))
                dt, name = float(data['dt']), str(data['lifting'])
                limit = float(data['force_limit'])
        except (KeyError, OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            # A truncated or corrupt .npz is a zip np.load cannot open: bad input, not a crash.
            raise ValueError(f'{path}: not a model written by rrtq identify '
                             f'({type(exc).__name__}: {exc})') from None
        p = a.shape[0]
        if a.shape != (p, p) or b.shape[0] != p or c.shape[1] != p or not dt > 0.0:
            raise ValueError(f'{path}: inconsistent shapes A {a.shape}, B {b.shape}, '
                             f'C {c.shape} or dt {dt}')
        if name not in table:
            raise ValueError(f'{path}: unknown lifting {name!r} (known: {sorted(table)})')
        return cls(a, b, c, dt, table[name], limit)


def fit_edmd(x: npt.ArrayLike, u: npt.ArrayLike, x_next: npt.ArrayLike, dt: float,
             lifting: Lifting | str = 'linear', ridge: float = 1e-9,
             force_limit: float = np.inf) -> KoopmanModel:
    """Least-squares EDMD with control on triples (x_k, u_k, x_{k+1}).

    ``[A B] = argmin sum ||psi(x_{k+1}) - A psi(x_k) - B u_k||² + ridge ||[A B]||_F²``,
    solved on column-scaled regressors so that metres and newtons weigh alike.
    """
    lift = LIFTINGS[lifting] if isinstance(lifting, str) else lifting
    xx, uu, xn = (np.atleast_2d(np.asarray(v, dtype=float)) for v in (x, u, x_next))
    if not (len(xx) == len(uu) == len(xn)):
        raise ValueError(f'x, u and x_next need one row per sample, got {len(xx)}, '
                         f'{len(uu)}, {len(xn)}')
    z, zn = lift(xx), lift(xn)
    n, p = xx.shape[1], z.shape[1]
    if not np.allclose(z[:, :n], xx):
        raise ValueError(f'lifting {lift.name!r}: its first {n} observables must be the state')
    reg = np.hstack((z, uu))
    scale = np.maximum(np.abs(reg).max(axis=0), 1e-12)
    rs = reg / scale
    gram = rs.T @ rs + ridge * len(rs) * np.eye(rs.shape[1])
    theta = np.linalg.solve(gram, rs.T @ zn).T / scale
    a, b = theta[:, :p], theta[:, p:]
    c = np.zeros((n, p))
    c[:, :n] = np.eye(n)
    return KoopmanModel(a, b, c, float(dt), lift, float(force_limit))


def prediction_errors(model: KoopmanModel, x: np.ndarray, u: np.ndarray,
                      x_next: np.ndarray, segments: list[tuple[int, int]],
                      horizon_steps: int) -> dict[str, list[float] | float | int]:
    """One-step RMSE per state component and open-loop error after ``horizon_steps``.

    ``segments`` are [start, end) row ranges of consecutive samples; every start with
    ``horizon_steps`` samples after it in its segment gives one open-loop rollout.
    """
    one = x_next - model.step(x, u)
    pos_err, vel_err = [], []
    for lo, hi in segments:
        for k in range(lo, hi - horizon_steps + 1):
            pred = model.rollout(x[k], u[k:k + horizon_steps])[-1]
            err = x_next[k + horizon_steps - 1] - pred
            pos_err.append(float(np.hypot(*err[:2])))
            vel_err.append(float(np.hypot(*err[2:4])) if err.size >= 4 else 0.0)
    pos = np.array(pos_err)
    return {
        'one_step_rmse': np.sqrt(np.mean(one ** 2, axis=0)).tolist(),
        'open_loop_windows': int(pos.size),
        'open_loop_position_rmse_m': float(np.sqrt(np.mean(pos ** 2))) if pos.size else
        float('nan'),
        'open_loop_position_max_m': float(pos.max()) if pos.size else float('nan'),
        'open_loop_velocity_rmse_mps': float(np.sqrt(np.mean(np.square(vel_err))))
        if vel_err else float('nan'),
    }
