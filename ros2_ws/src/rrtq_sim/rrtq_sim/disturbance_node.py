"""Disturbance injector: publishes d(t) on /disturbance, one value per plant step.

Lives on the simulator's side of the graph, so it may know the plant, and it reads the
true state (/odom/truth: the ``field`` model's position, the worst case's x̄), never the
robot's measurement. The ``worst_case`` model plays the zero-sum game's maximising player
d* = γ⁻²FᵀP(τ)x̄, with P the game Riccati solution of the controller's current leg
(:class:`rrtq_sim.disturbance.WorstCaseGame`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState, Disturbance

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Requirement, Step, StepGate
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import Dimensions, RunConfig
from rrtq_sim.conversions import disturbance_msg
from rrtq_sim.disturbance import (DisturbanceConfig, DisturbanceModel, WorstCaseGame,
                                  make_generator)


class DisturbanceNode(Node):
    """d(t) for every /odom/truth step (joined with /controller/state for worst_case)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('disturbance_injector', **NODE_OPTIONS, **kwargs)
        dims = declare_config(self, Dimensions)
        run = declare_config(self, RunConfig, exclude=('dt', 'lockstep'))
        self.config = declare_config(self, DisturbanceConfig, dims)
        worst = self.config.model is DisturbanceModel.WORST_CASE
        game = declare_config(self, WorstCaseGame, dims) if worst else None
        self.generator = make_generator(self.config, np.random.default_rng(run.seed), game)
        self.pub = self.create_publisher(Disturbance, topics.DISTURBANCE, qos.STREAM)
        # The worst case needs the controller's leg of the same step, in either mode.
        self.gate = StepGate([Requirement('state')] if worst else [], lockstep=True,
                             ordered=False, resend=self.pub.publish, on_step=self.publish)
        subscribe_inputs(self, self.gate, [Input('odom', Odometry, topics.ODOM_TRUTH,
                                                 qos.STREAM)] + (
            [Input('state', ControllerState, topics.CONTROLLER_STATE, qos.STREAM)] if worst
            else []))

    def publish(self, step: Step) -> None:
        state = step.get('state')
        target = None if state is None else (state.leg_target.x, state.leg_target.y)
        value = self.generator.value_at(step.stamp_ns * 1e-9, conv.odometry_state(step['odom']),
                                        target, 0.0 if state is None else state.time_to_go)
        msg = disturbance_msg(step.stamp_ns, self.config.model.value, value)
        self.gate.answered(step.stamp_ns, msg)
        self.pub.publish(msg)


def main(args: list[str] | None = None) -> None:
    spin_node(DisturbanceNode, args)


if __name__ == '__main__':
    main()
