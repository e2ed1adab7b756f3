"""Disturbance injector: publishes d(t) on /disturbance, one value per plant step.

Lives on the simulator's side of the graph, so it may know the plant: the
``worst_case`` model plays the zero-sum game's maximising player d* = γ⁻²FᵀP(τ)x̄,
with P the game Riccati solution of the controller's current leg.
"""

from __future__ import annotations

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState, Disturbance

from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.disturbance import DisturbanceGenerator, DisturbanceModel
from rrtq_sim.lockstep import StampJoin
from rrtq_sim.params import declare, spin_node
from rrtq_sim.riccati import solve_riccati


class DisturbanceNode(Node):
    """d(t) for every /odom step (joined with /controller/state for worst_case)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('disturbance_injector', **kwargs)
        d = lambda *a, **k: declare(self, *a, **k)  # noqa: E731
        self.model = DisturbanceModel(d('model', 'none', 'none | constant | sinusoid | '
                                        'gaussian | worst_case'))
        n = d('n', 4, 'plant state dimension', low=2)
        f = np.asarray(d('F', [0.0, 0.0, -1.0, 1.0], 'F, row-major (n x q)', element=float))
        self.F = f.reshape(n, -1)
        amplitude = d('amplitude', 1.0, 'constant value / sinusoid amplitude / gaussian '
                      'std / worst-case clip, in the units of d')
        frequency = d('frequency', 0.2, 'sinusoid frequency, Hz', low=0.0)
        seed = d('seed', 0, 'seed of the gaussian model', low=0)
        riccati = None
        gamma = None
        if self.model is DisturbanceModel.WORST_CASE:
            gamma = d('gamma', 3.0, 'attenuation level of the game', low=1e-9)
            mats = {name: np.asarray(d(name, [0.0], f'{name}, row-major', element=float))
                    for name in ('A', 'B', 'M', 'R', 'P_T')}
            a = mats['A'].reshape(n, n)
            b = mats['B'].reshape(n, -1)
            m = b.shape[1]
            riccati = solve_riccati(a, b, mats['M'].reshape(n, n), mats['R'].reshape(m, m),
                                    mats['P_T'].reshape(n, n),
                                    d('horizon', 10.0, 'leg horizon T, s', low=1e-3),
                                    F=self.F, gamma=gamma)
        self.generator = DisturbanceGenerator(
            self.model, self.F.shape[1], amplitude, frequency, np.random.default_rng(seed),
            riccati=riccati, F=self.F, gamma=gamma)
        self.pub = self.create_publisher(Disturbance, topics.DISTURBANCE, qos.STREAM)
        self.join = StampJoin(['odom', 'state'] if riccati is not None else ['odom'])
        self.last: Disturbance | None = None
        self.create_subscription(Odometry, topics.ODOM, self._joiner('odom'), qos.STREAM)
        if riccati is not None:
            self.create_subscription(ControllerState, topics.CONTROLLER_STATE,
                                     self._joiner('state'), qos.STREAM)

    def _joiner(self, key: str):
        def callback(msg) -> None:
            stamp = conv.stamp_ns(msg.header.stamp)
            if (key == 'odom' and self.last is not None
                    and stamp <= conv.stamp_ns(self.last.header.stamp)):
                self.pub.publish(self.last)   # a resent step: answer it again
                return
            done = self.join.add(key, stamp, msg)
            if done is not None:
                self.publish(stamp, done)
        return callback

    def publish(self, stamp: int, msgs: dict) -> None:
        x = conv.odometry_state(msgs['odom'])
        xbar, tau = x, 0.0
        if 'state' in msgs:
            state = msgs['state']
            xbar = x - np.array([state.leg_target.x, state.leg_target.y, 0.0, 0.0])
            tau = state.time_to_go
        value = self.generator.value(stamp * 1e-9, xbar, tau)
        self.last = conv.disturbance_msg(stamp, self.model.value, value)
        self.pub.publish(self.last)


def main(args: list[str] | None = None) -> None:
    spin_node(DisturbanceNode, args)


if __name__ == '__main__':
    main()
