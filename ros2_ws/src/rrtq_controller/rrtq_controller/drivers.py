"""The one place that picks a controller variant's driver (no rclpy).

Every driver is a :class:`rrtq_controller.driver.Driver`: the learning variants' and the
scripted force profile's are in :mod:`rrtq_controller.driver`, vf_lpc's in
:mod:`rrtq_controller.vf_lpc.driver`. This module imports them all and maps each
:class:`Variant` to its own (:data:`DRIVERS`); the node makes its driver with
:func:`make_driver`, and the orchestrator checks a scenario's variant against the table.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .config import ControllerConfig, Variant
from .driver import Driver, LearningDriver, OpenLoopDriver
from .vf_lpc.driver import VFLPCDriver

__all__ = ['DRIVERS', 'make_driver']

DRIVERS: dict[Variant, Callable[..., Driver]] = {
    Variant.NOMINAL: LearningDriver,
    Variant.ROBUST: LearningDriver,
    Variant.OPEN_LOOP: OpenLoopDriver,
    Variant.VF_LPC: VFLPCDriver,
}
"""The driver of each controller variant: a new variant registers its own here."""


def make_driver(config: ControllerConfig, n: int, m: int, q: int,
                rng: np.random.Generator, **extra: Any) -> Driver:
    """The driver of ``config.variant`` (``extra``: its own settings, e.g. vf_lpc's ``lpc``)."""
    return DRIVERS[config.variant](config, n, m, q, rng, **extra)
