"""Online sparse GP (FITC, Snelson & Ghahramani 2005) on an ALD dictionary (VF-LPC §III-C, §IV-B).

Per output j, the latent residual g_j(z) has the prior ``GP(0, s_j² k(z, z'))`` with the
squared-exponential kernel ``k = exp(-½ sum_d ((z_d - z'_d)/l_d)²)`` (eq. 6) shared by
all outputs. FITC conditions every observation on the inducing values ``u_j = g_j(D)``
at the dictionary D alone, with the exact marginal variance:
``y = h(z)ᵀ u_j + e``, ``h = K_DD⁻¹ k_D(z)``, ``var e = s_j² delta(z) + sigma_j²``,
``delta(z) = 1 - k_D(z)ᵀ K_DD⁻¹ k_D(z)`` (the ALD residual). The posterior over u_j is
Gaussian, ``N(mu_j, S_j)``, and each observation updates it exactly as a Kalman step
(O(M²)); predictions (eq. 7): ``mean = h(z)ᵀ mu_j``,
``var = s_j² delta(z) + h(z)ᵀ S_j h(z)`` (latent; add sigma_j² for an observation).

Dictionary (ALD, Engel et al. 2004): a point joins when ``delta(z) > nu``. Joining extends
the posterior by the prior conditional of the new inducing value given the old ones, and
K_DD⁻¹ by its block inverse; when the dictionary is full, the oldest point is first
marginalised out (rows and columns dropped, K_DD⁻¹ downdated). Every operation is O(M²)
for M dictionary points (times the outputs for S_j), so one update costs O(q M² + M d).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rrtq_common.settings import check, setting

__all__ = ['SparseGPConfig', 'OnlineSparseGP']


@dataclass(frozen=True)
class SparseGPConfig:
    """Hyperparameters and dictionary of the online FITC GP.

    Every field is a :func:`rrtq_common.settings.setting`; the three tuples must be
    non-empty and finite, ``signal_std`` and ``noise_std`` of one length (the outputs).
    """

    lengthscales: tuple[float, ...] = setting(
        low=0.0, low_open=True, doc="l_d, one per input dimension, in that input's unit")
    signal_std: tuple[float, ...] = setting(
        low=0.0, low_open=True, doc="s_j, one per output, in that output's unit")
    noise_std: tuple[float, ...] = setting(
        low=0.0, low_open=True,
        doc="sigma_j, one per output (observation noise), in that output's unit")
    max_dictionary: int = setting(60, low=1, high=2000,
                                  doc='M: the dictionary never holds more points')
    ald_threshold: float = setting(
        0.1, low=0.0, high=1.0, low_open=True, high_open=True,
        doc='nu (of the unit-variance kernel): the ALD residual above which a point joins '
        'the dictionary')

    def __post_init__(self) -> None:
        for name in ('lengthscales', 'signal_std', 'noise_std'):
            values = tuple(float(v) for v in getattr(self, name))
            if not values or not all(math.isfinite(v) for v in values):
                raise ValueError(f'{name} must be positive and finite, got {values}')
            object.__setattr__(self, name, values)
        if len(self.signal_std) != len(self.noise_std):
            raise ValueError('signal_std and noise_std need one value per output')
        check(self)


class OnlineSparseGP:
    """FITC posterior on a bounded ALD dictionary, updated one observation at a time."""

    JITTER = 1e-10

    def __init__(self, config: SparseGPConfig) -> None:
        self.config = config
        self._inv_l = 1.0 / np.asarray(config.lengthscales)
        self.d = len(config.lengthscales)
        self.q = len(config.signal_std)
        self._s2 = np.asarray(config.signal_std) ** 2
        self._n2 = np.asarray(config.noise_std) ** 2
        m = config.max_dictionary
        self._D = np.zeros((0, self.d))          # dictionary, scaled by 1/l
        self._kinv = np.zeros((0, 0))            # K_DD^-1 of the unit kernel
        self._mu = np.zeros((self.q, 0))         # posterior means of u_j
        self._S = np.zeros((self.q, 0, 0))       # posterior covariances of u_j
        self._age = np.zeros(0, dtype=np.int64)
        self._capacity = m
        self.updates = 0

    @property
    def size(self) -> int:
        """Dictionary points held."""
        return self._D.shape[0]

    @property
    def dictionary(self) -> np.ndarray:
        """(M, d) dictionary inputs, in the inputs' units."""
        return self._D / self._inv_l

    @property
    def noise_var(self) -> np.ndarray:
        """(q,) sigma_j²."""
        return self._n2.copy()

    def _scaled(self, z: npt.ArrayLike) -> np.ndarray:
        return np.atleast_2d(np.asarray(z, dtype=float)) * self._inv_l

    def _k(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        sq = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
        return np.exp(-0.5 * np.maximum(sq, 0.0))

    def update(self, z: npt.ArrayLike, y: npt.ArrayLike) -> bool:
        """Absorb one observation y (q,) at input z (d,); True when z joined the dictionary."""
        zs = self._scaled(z)
        yy = np.asarray(y, dtype=float).reshape(self.q)
        added = False
        k = self._k(self._D, zs)[:, 0] if self.size else np.zeros(0)
        h = self._kinv @ k
        delta = max(1.0 - float(k @ h), 0.0)
        if delta > self.config.ald_threshold:
            if self.size >= self._capacity:
                self._drop(int(np.argmin(self._age)))
                k = self._k(self._D, zs)[:, 0] if self.size else np.zeros(0)
                h = self._kinv @ k
                delta = max(1.0 - float(k @ h), 0.0)
            self._add(zs[0], h, delta)
            added = True
            h = np.zeros(self.size)
            h[-1] = 1.0
            delta = 0.0
        # FITC observation of u_j through h, variance s_j² delta + sigma_j² (Kalman step).
        sh = self._S @ h                                   # (q, M)
        s = sh @ h + self._s2 * delta + self._n2           # (q,)
        gain = sh / s[:, None]
        self._mu += gain * (yy - self._mu @ h)[:, None]
        self._S -= gain[:, :, None] * sh[:, None, :]
        self._S = 0.5 * (self._S + np.swapaxes(self._S, 1, 2))
        self.updates += 1
        return added

    def _add(self, zs: np.ndarray, h: np.ndarray, delta: float) -> None:
        """Join zs: block inverse of K_DD and the prior conditional of its inducing value."""
        delta = max(delta, self.JITTER)
        m = self.size
        kinv = np.empty((m + 1, m + 1))
        kinv[:m, :m] = self._kinv + np.outer(h, h) / delta
        kinv[:m, m] = kinv[m, :m] = -h / delta
        kinv[m, m] = 1.0 / delta
        self._kinv = kinv
        sh = self._S @ h                                   # (q, M)
        S = np.empty((self.q, m + 1, m + 1))
        S[:, :m, :m] = self._S
        S[:, :m, m] = S[:, m, :m] = sh
        S[:, m, m] = sh @ h + self._s2 * delta
        self._S = S
        self._mu = np.hstack((self._mu, (self._mu @ h)[:, None]))
        self._D = np.vstack((self._D, zs))
        self._age = np.r_[self._age, self.updates]

    def _drop(self, i: int) -> None:
        """Marginalise dictionary point i out of the posterior; downdate K_DD^-1."""
        keep = np.r_[0:i, i + 1:self.size]
        p = self._kinv
        self._kinv = p[np.ix_(keep, keep)] - np.outer(p[keep, i], p[i, keep]) / p[i, i]
        self._S = self._S[:, keep][:, :, keep]
        self._mu = self._mu[:, keep]
        self._D = self._D[keep]
        self._age = self._age[keep]

    def predict(self, z: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Latent mean and variance (N, q) at inputs (N, d) (eq. 7)."""
        zs = self._scaled(z)
        if not self.size:
            return np.zeros((len(zs), self.q)), np.tile(self._s2, (len(zs), 1))
        k = self._k(zs, self._D)                           # (N, M)
        h = k @ self._kinv                                 # (N, M)
        mean = h @ self._mu.T
        delta = np.maximum(1.0 - np.einsum('nm,nm->n', h, k), 0.0)
        var = self._s2[None, :] * delta[:, None] + np.einsum('nm,qmk,nk->nq', h, self._S, h)
        return mean, np.maximum(var, 0.0)

    def mean_and_jacobian(self, z: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Mean (N, q) and its Jacobian d mean / d z (N, q, d) (eq. 21)."""
        zs = self._scaled(z)
        if not self.size:
            return np.zeros((len(zs), self.q)), np.zeros((len(zs), self.q, self.d))
        k = self._k(zs, self._D)                           # (N, M)
        alpha = self._kinv @ self._mu.T                    # (M, q)
        mean = k @ alpha
        # d k(z, D_i)/dz = -k (z - D_i) / l² (z, D_i scaled by 1/l, hence one more 1/l).
        diff = zs[:, None, :] - self._D[None, :, :]        # (N, M, d)
        jac = -np.einsum('nm,mq,nmd->nqd', k, alpha, diff) * self._inv_l[None, None, :]
        return mean, jac
