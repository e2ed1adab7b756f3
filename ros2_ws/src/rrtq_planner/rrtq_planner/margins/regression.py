"""The residual's field over the plane, with a simultaneous confidence band (``docs/margins.md`` §3).

Jha regresses the residual on the state with an LS-SVM (eqs. 3-4). Here the LS-SVM is
solved in its primal with a fixed, finite feature map (Suykens' fixed-size LS-SVM; the
same as a sparse GP with inducing points on a grid): Gaussian radial basis functions
φ(p) on a square grid of centres over the region. With V = λI + Σ φφᵀ (the regularised
normal matrix; γ of eq. 3 is 1/λ), the fit per output component c is ŵ_c = V⁻¹ Σ φ y_c and
d̂_c(p) = φ(p)ᵀŵ_c (eq. 4 in primal form).

Two bands:

* :meth:`FieldFit.pointwise_band`: the paper's eq. 9 with the bias (eq. 7) and variance
  (eq. 8) estimates. It holds at each p separately; its supremum over a region is not
  covered with 1 − δ (a region holds many nearly independent points).
* :meth:`FieldFit.band`: simultaneous over every p and every sample count at once — the
  self-normalised bound of Abbasi-Yadkori, Pál & Szepesvári (2011, Theorem 2): if
  y_c = φᵀw*_c + ε with ε conditionally σ_c-sub-Gaussian given the past (data gathered in
  closed loop are allowed) and ‖w*_c‖ ≤ S_c, then with probability ≥ 1 − δ_c, for all n,
  ‖ŵ_c − w*_c‖_V ≤ β_c = σ_c √(2 ln(1/δ_c) + ln det V − p ln λ) + √λ S_c, and by
  Cauchy-Schwarz |d̂_c(p) − d_c(p)| ≤ β_c ‖φ(p)‖_{V⁻¹} for all p. A union bound over the
  components gives δ_c = δ / (number of components).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.stats import norm

__all__ = ['RBFFeatures', 'FieldStatistics', 'FieldFit', 'fit_field']


class RBFFeatures:
    """Gaussian radial basis functions on a square grid of centres covering a box.

    Parameters
    ----------
    bounds
        ((x_min, x_max), (y_min, y_max)), m: the region the field is learned on; the grid
        extends one spacing beyond it so that the edges are covered as well as the inside.
    spacing
        Distance between centres, m; also the length scale of each function.
    """

    def __init__(self, bounds: tuple[tuple[float, float], tuple[float, float]],
                 spacing: float) -> None:
        if not spacing > 0.0:
            raise ValueError(f'spacing must be > 0, got {spacing!r}')
        (x0, x1), (y0, y1) = bounds
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f'bounds must be ((x_min, x_max), (y_min, y_max)), got {bounds!r}')
        self.bounds = ((float(x0), float(x1)), (float(y0), float(y1)))
        self.spacing = float(spacing)
        xs = np.arange(x0 - spacing, x1 + spacing + 1e-9, spacing)
        ys = np.arange(y0 - spacing, y1 + spacing + 1e-9, spacing)
        gx, gy = np.meshgrid(xs, ys, indexing='ij')
        self.centers = np.column_stack([gx.ravel(), gy.ravel()])
        self._inv2l2 = 0.5 / spacing**2

    @property
    def size(self) -> int:
        """p, the number of features."""
        return len(self.centers)

    def __call__(self, positions: npt.ArrayLike) -> np.ndarray:
        """φ(p) for positions (k, 2) (or one (2,)): shape (k, p) (or (p,))."""
        p = np.asarray(positions, dtype=float)
        pts = p.reshape(-1, p.shape[-1])[:, :2]
        d2 = ((pts[:, None, :] - self.centers[None]) ** 2).sum(axis=2)
        out = np.exp(-self._inv2l2 * d2)
        return out[0] if p.ndim == 1 else out


@dataclasses.dataclass
class FieldStatistics:
    """Sufficient statistics of a regression of outputs y (n_out) on φ(p) (p features).

    Optionally also on a model regressor z (d) fitted jointly (the one-step model,
    :mod:`.learned`).
    """

    gram: np.ndarray
    """Σ φφᵀ, (p, p)."""
    moment: np.ndarray
    """Σ φ yᵀ, (p, n_out)."""
    square: np.ndarray
    """Σ y_c², (n_out,)."""
    count: int = 0
    model_gram: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    """Σ z zᵀ, (d, d)."""
    cross: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    """Σ φ zᵀ, (p, d)."""
    model_moment: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    """Σ z yᵀ, (d, n_out)."""

    @classmethod
    def zeros(cls, p: int, n_out: int, d: int = 0) -> FieldStatistics:
        return cls(np.zeros((p, p)), np.zeros((p, n_out)), np.zeros(n_out), 0,
                   np.zeros((d, d)), np.zeros((p, d)), np.zeros((d, n_out)))

    def add(self, phi: np.ndarray, y: np.ndarray, z: np.ndarray | None = None) -> None:
        """Account one sample (φ(p), y) (and z when the model is fitted jointly)."""
        self.gram += np.outer(phi, phi)
        self.moment += np.outer(phi, y)
        self.square += y * y
        if z is not None:
            self.model_gram += np.outer(z, z)
            self.cross += np.outer(phi, z)
            self.model_moment += np.outer(z, y)
        self.count += 1

    def __add__(self, other: FieldStatistics) -> FieldStatistics:
        return FieldStatistics(self.gram + other.gram, self.moment + other.moment,
                               self.square + other.square, self.count + other.count,
                               self.model_gram + other.model_gram, self.cross + other.cross,
                               self.model_moment + other.model_moment)


@dataclasses.dataclass(frozen=True)
class FieldFit:
    """A fitted field: weights, noise, the confidence multipliers, and what the bands need.

    With a jointly fitted model, ``_chol`` factors the Schur complement S of the model
    block in V, so that ‖φ‖_{S⁻¹} is the field's part of ‖(0, φ)‖_{V⁻¹} and the bands hold
    with the model's own uncertainty accounted for.
    """

    weights: np.ndarray
    """ŵ, (p, n_out)."""
    model: np.ndarray
    """Θ̂ (n_out, d) of the jointly fitted regressor z; (n_out, 0) without one."""
    sigma: np.ndarray
    """σ_c used in the band, (n_out,): the estimate, at least the floor."""
    noise_beta: np.ndarray
    """σ_c √(2 ln(n_out/δ) + ln det V − p ln λ), (n_out,): the noise part of β_c."""
    weight_bound: np.ndarray
    """S_c, (n_out,)."""
    ridge: float
    count: int
    _chol: tuple[np.ndarray, bool]
    _gram: np.ndarray

    @property
    def beta(self) -> np.ndarray:
        """β_c = noise part + √λ S_c, (n_out,)."""
        return self.noise_beta + math.sqrt(self.ridge) * self.weight_bound

    def with_weight_bound(self, weight_bound: npt.ArrayLike) -> FieldFit:
        """The same fit with another S_c."""
        s = np.broadcast_to(np.asarray(weight_bound, dtype=float), self.sigma.shape).copy()
        return dataclasses.replace(self, weight_bound=s)

    def mean(self, phi: np.ndarray) -> np.ndarray:
        """d̂(p) at feature rows (k, p): (k, n_out)."""
        return phi @ self.weights

    def spread(self, phi: np.ndarray) -> np.ndarray:
        """‖φ(p)‖_{V⁻¹} at feature rows (k, p): (k,).

        One triangular solve: with V = UᵀU (or LLᵀ), φᵀV⁻¹φ = ‖U⁻ᵀφ‖² (‖L⁻¹φ‖²).
        """
        factor, lower = self._chol
        half = solve_triangular(factor, phi.T, lower=lower, trans='N' if lower else 'T',
                                check_finite=False)
        return np.sqrt((half * half).sum(axis=0))

    def band(self, phi: np.ndarray, spread: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
        """Simultaneous band (mean, half-width), each (k, n_out): Abbasi-Yadkori et al. Thm 2.

        ``spread``: :meth:`spread` at the same rows, when the caller has it already.
        """
        if spread is None:
            spread = self.spread(phi)
        return self.mean(phi), spread[:, None] * self.beta[None, :]

    def pointwise_band(self, phi: np.ndarray, delta: float) -> tuple[np.ndarray, np.ndarray]:
        """Jha's eq. 9, (centre, half-width) each (k, n_out), for comparison only.

        Centre d̂(p) − bias (eq. 7, the smoother applied to the fit minus the fit); half-width
        z_{1−δ/2} √Var (eq. 8, homoscedastic: σ² ‖L(p)‖², L(p) = Φ V⁻¹ φ(p) the smoother row).
        """
        sol = cho_solve(self._chol, phi.T)                       # V⁻¹ φ, (p, k)
        mean = self.mean(phi)
        bias = (self._gram @ sol).T @ self.weights - mean        # L(p)ᵀ Φ ŵ − d̂(p)
        var = (sol * (self._gram @ sol)).sum(axis=0)            # φᵀ V⁻¹ G V⁻¹ φ
        half = norm.ppf(1.0 - 0.5 * delta) * np.sqrt(np.maximum(var, 0.0))[:, None] * self.sigma
        return mean - bias, half


def fit_field(stats: FieldStatistics, ridge: float, delta: float, weight_bound: npt.ArrayLike,
              noise_floor: npt.ArrayLike = 0.0, noise: npt.ArrayLike | None = None,
              model_prior: tuple[np.ndarray, float] | None = None) -> FieldFit:
    """Fit the field (and the model, when ``stats`` has one) with its simultaneous band.

    Parameters
    ----------
    stats
        Sufficient statistics.
    ridge
        λ > 0 of the field's weights (dimensionless: the features are of order 1).
    delta
        δ of the band for all components together (each gets δ / n_out).
    weight_bound
        S_c, a bound of ‖w*_c‖ (units of y), scalar or per component: the smoothness the
        band assumes of the field (the data cannot check it; see ``docs/margins.md``).
    noise_floor
        Lower bound of σ_c (units of y).
    noise
        σ_c when known (synthetic tests); default: estimated from the fit's residuals,
        σ̂_c² = RSS_c / (n − degrees of freedom), a plug-in that makes the band approximate.
    model_prior
        (Θ₀ (n_out, d), μ): prior mean and precision of the model's coefficients, required
        when ``stats`` has a model block. The model's share of β (√μ ‖Θ* − Θ₀‖) is taken as 0:
        μ is meant to be negligible.
    """
    p, n_out = stats.moment.shape
    d = stats.model_gram.shape[0]
    lam = ridge * np.eye(p)
    if d:
        if model_prior is None:
            raise ValueError('a model block needs model_prior = (mean, precision)')
        theta0, mu = np.asarray(model_prior[0], dtype=float), float(model_prior[1])
        cz = cho_factor(stats.model_gram + mu * np.eye(d))
        rhs_z = stats.model_moment + mu * theta0.T                  # (d, n_out)
        a = cho_solve(cz, stats.cross.T)                            # Mz⁻¹ Σzφᵀ, (d, p)
        S = stats.gram + lam - stats.cross @ a
        chol = cho_factor(S)
        w = cho_solve(chol, stats.moment - stats.cross @ cho_solve(cz, rhs_z))
        theta_t = cho_solve(cz, rhs_z - stats.cross.T @ w)          # Θ̂ᵀ, (d, n_out)
        logdet_model = 2.0 * float(np.log(np.diag(cz[0])).sum()) - d * math.log(mu)
        s_inv = cho_solve(chol, np.eye(p))
        penalty = mu * (float(np.trace(cho_solve(cz, np.eye(d)))) + float(np.sum(a * (a @ s_inv))))
    else:
        chol = cho_factor(stats.gram + lam)
        w = cho_solve(chol, stats.moment)
        theta_t = np.zeros((0, n_out))
        logdet_model, penalty = 0.0, 0.0
        s_inv = cho_solve(chol, np.eye(p))
    if noise is None:
        rss = (stats.square - 2.0 * (w * stats.moment).sum(axis=0) + (w * (stats.gram @ w)).sum(axis=0)
               - 2.0 * (theta_t * stats.model_moment).sum(axis=0)
               + 2.0 * (theta_t * (stats.cross.T @ w)).sum(axis=0)
               + (theta_t * (stats.model_gram @ theta_t)).sum(axis=0))
        dof = d + p - penalty - ridge * float(np.trace(s_inv))
        sigma = np.sqrt(np.maximum(rss, 0.0) / max(stats.count - dof, 1.0))
    else:
        sigma = np.broadcast_to(np.asarray(noise, dtype=float), (n_out,)).copy()
    sigma = np.maximum(sigma, np.broadcast_to(np.asarray(noise_floor, dtype=float), (n_out,)))
    logdet = 2.0 * float(np.log(np.diag(chol[0])).sum()) - p * math.log(ridge) + logdet_model
    noise_beta = sigma * math.sqrt(2.0 * math.log(n_out / delta) + logdet)
    bound = np.broadcast_to(np.asarray(weight_bound, dtype=float), (n_out,)).copy()
    gram_eff = stats.gram - (stats.cross @ a if d else 0.0)
    return FieldFit(w, theta_t.T.copy(), sigma, noise_beta, bound, ridge, stats.count, chol,
                    np.asarray(gram_eff))
