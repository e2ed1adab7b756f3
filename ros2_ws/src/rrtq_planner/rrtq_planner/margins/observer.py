"""A safety-side one-step model of the robot, learned by recursive least squares.

The safety node does not know the plant (docs/design.md, Plant: its matrices are the simulator's
secret) and does not ask the controller; it fits, from what it measures (``/odom``) and what
was commanded (``/cmd_force``), the linear one-step map

    x̄_{k+1} ≈ Φ̂ x̄_k + Γ̂ u_k,

with x̄ the state relative to the frame in which the plant is time-invariant: the leg's
target at rest when the rover's spring is anchored there, the world origin when it is
anchored at the origin (either, without a spring). What the model does not explain,
w_k = x̄_{k+1} − Φ̂x̄_k − Γ̂u_k, is the residual of Jha's eq. 2, which :mod:`.regression`
learns as a function of position. (A regressor for the leg target's position, which would
serve both anchors with one model, was tried and dropped: it is constant over a leg and
soaks up whatever the disturbance is on that leg, which then goes missing from the residual.)
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ['OneStepModel']


class OneStepModel:
    """Recursive least squares for Θ = [Φ | Γ] on the regressor z = (x̄, u).

    Parameters
    ----------
    n, m
        State and input dimensions (the first two state components are the position).
    prior_variance
        Initial covariance of every coefficient (scaled by the noise): large is
        uninformative. The prior mean is Φ = I, Γ = 0 (the state persists over one
        short step), so a few samples already give a usable model.
    forgetting
        λ in (0, 1]: weight of the past per sample; 1 keeps all data (a time-invariant plant).
    """

    def __init__(self, n: int, m: int, prior_variance: float = 1e6,
                 forgetting: float = 1.0) -> None:
        if not 0.0 < forgetting <= 1.0:
            raise ValueError(f'forgetting must be in (0, 1], got {forgetting!r}')
        if not prior_variance > 0.0:
            raise ValueError(f'prior_variance must be > 0, got {prior_variance!r}')
        self.n, self.m = n, m
        self.dim = n + m
        self.theta = np.zeros((n, self.dim))
        self.theta[:, :n] = np.eye(n)
        self.P = prior_variance * np.eye(self.dim)
        self.forgetting = float(forgetting)
        self.samples = 0

    def regressor(self, x_bar: npt.ArrayLike, u: npt.ArrayLike) -> np.ndarray:
        """The regressor z = (x̄, u)."""
        return np.concatenate([np.asarray(x_bar, float).reshape(-1),
                               np.asarray(u, float).reshape(-1)])

    def residual(self, z: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The residual w = y − Θ̂ z with the current estimate."""
        return y - self.theta @ z

    def update(self, z: np.ndarray, y: np.ndarray) -> np.ndarray:
        """One RLS step on the pair (z_k, x̄_{k+1}); returns the a-priori residual."""
        e = self.residual(z, y)
        pz = self.P @ z
        gain = pz / (self.forgetting + z @ pz)
        self.theta += np.outer(e, gain)
        self.P = (self.P - np.outer(gain, pz)) / self.forgetting
        self.P = 0.5 * (self.P + self.P.T)
        self.samples += 1
        return e

    @property
    def phi(self) -> np.ndarray:
        """Φ̂ (n x n)."""
        return self.theta[:, :self.n]

    @property
    def gamma(self) -> np.ndarray:
        """Γ̂ (n x m)."""
        return self.theta[:, self.n:self.n + self.m]
