"""What the nodes of one run share: the step, lock-step or paced, the seed, the dimensions."""

from __future__ import annotations

from dataclasses import dataclass

from rrtq_common.settings import setting

__all__ = ['READY_PARAMETER', 'STEP_S', 'RunConfig', 'Dimensions']

STEP_S = 0.05
"""The default step Δt of a run, s: the controller's period, the plant's step, the stamps."""
READY_PARAMETER = 'ready_when_matched'
"""The start-up handshake's parameter of a node (rrtq_common.readiness): ``topic:count``."""


@dataclass(frozen=True)
class RunConfig:
    """Settings every node of a run takes from the orchestrator."""

    dt: float = setting(STEP_S, unit='s', low=0.0, low_open=True,
                        doc='step of the simulation; lock-step stamps are its multiples')
    lockstep: bool = setting(False, doc='true: a step is processed once its inputs are all '
                             'in (--speed max); false: paced, with the latest inputs')
    seed: int = setting(0, low=0, doc="seed of the node's numpy.random.Generator")


@dataclass(frozen=True)
class Dimensions:
    """Sizes of the plant's vectors (the rover's by default); matrices are sized by them."""

    n: int = setting(4, low=2, doc='state dimension (components 0 and 1: the position, m)')
    m: int = setting(2, low=1, doc='input dimension (forces, N)')
    q: int = setting(1, low=0, doc='disturbance dimension')
