"""The actor's gain K̂(τ) from its weights as /controller/state reports them (no rclpy import).

The one reading of the controller's actor weights for the nodes and tools that are not the
controller: the safety node's learned_bound tube (``rrtq_planner``) and the leg tables
(``rrtq_bringup.leg_table``). The controller's own readout is
``rrtq_controller.readout.WeightReadout.gain`` on its ``basis.TimeBasis``; tests hold the
two equal.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt


def actor_gain(weights: npt.ArrayLike, rates: Sequence[float], powers: Sequence[float],
               horizon: float, n: int, m: int) -> Callable[[float], np.ndarray] | None:
    """K̂(τ) (m x n) of the actor's weights Ŵa ((L n) x m, flat), u = −K̂(τ)x̄ + probing.

    The time basis is the controller's as /controller/state reports it: exp(−λ τ) for each
    rate, then (τ / T)^k for each power, τ clipped at 0. Weights of the exponentials alone
    are read on those: weights recorded before the controller widened its basis
    (:meth:`rrtq_controller.q_learning.QLearningController.widen_time_basis`), read on the
    last recorded basis (the leg tables). None when the weights fit neither (no actor:
    open loop, or before the first state).
    """
    w = np.asarray(weights, dtype=float)
    lam, k = np.asarray(rates, dtype=float), np.asarray(powers, dtype=float)
    if w.size != (lam.size + k.size) * n * m and w.size == lam.size * n * m:
        k = k[:0]   # recorded before the controller widened its basis
    size = lam.size + k.size
    if size == 0 or w.size != size * n * m or horizon <= 0.0:
        return None
    table = w.reshape(size, n, m)

    def gain(tau: float) -> np.ndarray:
        t = max(tau, 0.0)
        phi = np.concatenate([np.exp(-lam * t), (t / horizon) ** k])
        return np.asarray(-np.einsum('l,lij->ji', phi, table))
    return gain
