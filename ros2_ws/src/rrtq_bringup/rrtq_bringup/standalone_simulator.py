"""The simulator of ``rrtq plant``: the run's simulator node, holding zero force without commands.

Paced, it holds the newest command; one not renewed for ``command_timeout_s`` of sim time
counts as missing (:class:`rrtq_bringup.plant_process.CommandHold`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rrtq_bringup.plant_process import CommandHold, PlantProcessConfig
from rrtq_common.lockstep import seconds_to_ns
from rrtq_common.params import declare_config
from rrtq_sim.simulator_node import SimulatorNode


class StandaloneSimulatorNode(SimulatorNode):
    """:class:`rrtq_sim.simulator_node.SimulatorNode` whose held force expires."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        config = declare_config(self, PlantProcessConfig)
        self.command = CommandHold(seconds_to_ns(config.command_timeout_s))

    def _hold(self, key: str, msg: Any) -> None:
        super()._hold(key, msg)
        if key == 'cmd_force' and self.command.received(self.sim.now_ns):
            self.get_logger().info(f't={self.sim.now_ns * 1e-9:.2f} s: commands are back')

    def advance(self) -> None:
        if self.command.expired(self.sim.now_ns):
            self.sim.hold_force(np.zeros(self.sim.plant.m))
            self.get_logger().warning(
                f't={self.sim.now_ns * 1e-9:.2f} s: no /cmd_force for more than '
                f'{self.command.timeout_ns * 1e-9:g} s of sim time: holding zero force')
        super().advance()
