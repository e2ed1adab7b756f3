"""Simulator node: owns /clock, steps the plant, publishes /odom and /odom/truth every step.

/odom is what the robot measures (the true state with the scenario's odometry noise, its
covariance filled in: :mod:`rrtq_sim.odometry`); /odom/truth is the true state, for the
simulator's side and the recording. A commanded force acts ``plant.actuation_delay``
later (:class:`rrtq_sim.simulation.DelayLine`).

With ``model`` mujoco the plant is :class:`rrtq_sim.mujoco_plant.MujocoPlant`, built with
the obstacles of the scenario file (``scenario``); a step during which the robot touched
one is announced on /plant/contact before its odometry.

Lock-step (``speed`` = 0, the CLI's ``--speed max``): step k+1 is taken only when every
topic in ``acks`` has delivered its message stamped with step k's time, so a run is a
function of its inputs alone. Paced (``speed`` > 0): a wall timer steps the plant at
``speed`` times real time with the latest inputs.
"""

from __future__ import annotations

import time
from typing import Any

from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from rrtq_msgs.msg import ControllerState, Disturbance, PerceptionStatus, PlantContact
from std_msgs.msg import Empty, String

from rrtq_common import conversions as conv
from rrtq_common import qos, readiness, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Requirement, Step, StepGate
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import Dimensions, RunConfig
from rrtq_sim.disturbance import DisturbanceConfig
from rrtq_common.world import TrueObstacles
from rrtq_common.world_yaml import WorldSource, load_world
from rrtq_sim.conversions import plant_contact_msg
from rrtq_sim.mujoco_model import BaseParameters, coulomb_force
from rrtq_sim.mujoco_plant import MujocoPlant
from rrtq_sim.odometry import OdometryNoise, OdometryNoiseConfig, odometry_rng
from rrtq_sim.plant import Plant, PlantConfig, PlantModel
from rrtq_sim.simulation import Simulation, SimulatorConfig, delay_steps

ACK_TOPICS = {'cmd_force': (topics.CMD_FORCE, WrenchStamped),
              'controller_state': (topics.CONTROLLER_STATE, ControllerState),
              'disturbance': (topics.DISTURBANCE, Disturbance),
              'perception_status': (topics.PERCEPTION_STATUS, PerceptionStatus)}
# What the plant holds from each input; the others only acknowledge a step.
INPUTS = ('cmd_force', 'controller_state', 'disturbance')


class SimulatorNode(Node):
    """The plant, its clock and its odometry."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('simulator', **NODE_OPTIONS, **kwargs)
        dims = declare_config(self, Dimensions, exclude=('m', 'q'))
        run = declare_config(self, RunConfig, exclude=('lockstep',))
        plant = declare_config(self, PlantConfig, dims, exclude=('stiffness',))
        disturbance = declare_config(self, DisturbanceConfig, dims,
                                     exclude=('model', 'amplitude', 'frequency', 'gamma'))
        self.config = declare_config(self, SimulatorConfig)
        delay = delay_steps(plant.actuation_delay, run.dt)
        if plant.model is PlantModel.MUJOCO:
            world = load_world(declare_config(self, WorldSource).scenario)
            physics = MujocoPlant(world.obstacles, run.dt, plant.force_limit, disturbance.F,
                                  BaseParameters(plant.mass, plant.damping,
                                                 coulomb_force(plant.friction, plant.mass),
                                                 world.robot_radius), plant.mjcf)
            self.sim = Simulation(physics, self.config.start, plant.spring_anchor,
                                  self.config.duration, delay, TrueObstacles.for_scenario(world))
        else:
            self.sim = Simulation(Plant(plant.A, plant.B, disturbance.F, run.dt,
                                        plant.force_limit),
                                  self.config.start, plant.spring_anchor, self.config.duration,
                                  delay)
        self.noise = OdometryNoise(declare_config(self, OdometryNoiseConfig),
                                   odometry_rng(run.seed))
        self._last_odometry: tuple[Odometry, Odometry] | None = None
        self.started = False
        self.wall_start: float | None = None
        self._last_publish = time.monotonic()
        self.clock_pub = self.create_publisher(Clock, topics.CLOCK, qos.CLOCK)
        self.odom_pub = self.create_publisher(Odometry, topics.ODOM, qos.STREAM)
        self.truth_pub = self.create_publisher(Odometry, topics.ODOM_TRUTH, qos.STREAM)
        self.contact_pub = (self.create_publisher(PlantContact, topics.PLANT_CONTACT, qos.STREAM)
                            if plant.model is PlantModel.MUJOCO else None)
        self.gate = StepGate([Requirement(key) for key in self.config.acks],
                             lockstep=self.config.speed == 0.0, driver=None, ordered=False,
                             on_step=self._on_step)
        subscribe_inputs(self, self.gate, [
            Input(key, ACK_TOPICS[key][1], ACK_TOPICS[key][0], qos.STREAM)
            for key in sorted(set(self.config.acks) | set(INPUTS))])
        self.create_subscription(Empty, topics.SIMULATOR_PAUSE, self._pause, qos.LATCHED)
        self._wait_for = readiness.expectations(self.config.wait_for, 'wait_for')
        self.ready: set[str] = set()
        self.create_subscription(String, topics.GRAPH_READY,
                                 lambda msg: self.ready.add(msg.data), readiness.QOS)
        self._ready_since: float | None = None
        self._start_timer = self.create_timer(0.02, self._try_start)

    @property
    def rejected_inputs(self) -> int:
        """Inputs that were not finite or misshapen (zero was held instead)."""
        return self.sim.rejected

    # -- inputs ---------------------------------------------------------------
    def _on_step(self, step: Step) -> None:
        """Hold the inputs; lock-step: take the next step once this one is acknowledged."""
        if self.gate.lockstep and step.stamp_ns != self.sim.now_ns:
            return
        for name, message in sorted(step.messages.items()):
            self._hold(name, message)
        if self.gate.lockstep:
            self.advance()

    def _hold(self, key: str, msg: Any) -> None:
        if key == 'cmd_force':
            u = [msg.wrench.force.x, msg.wrench.force.y]
            if not self.sim.hold_force(u):
                self._warn_rejected('cmd_force', u)
        elif key == 'disturbance':
            if not self.sim.hold_disturbance(msg.value):
                self._warn_rejected('disturbance', list(msg.value))
        elif key == 'controller_state':
            self.sim.follow_target([msg.leg_target.x, msg.leg_target.y])

    def _warn_rejected(self, what: str, value: list[float]) -> None:
        self.get_logger().warning(f'rejected {what} {value}: applying zero',
                                  throttle_duration_sec=1.0)

    # -- stepping -------------------------------------------------------------
    def _graph_ready(self) -> bool:
        if waiting := sorted(set(self.config.ready_from) - self.ready):
            self.get_logger().info(f'waiting for the writers of {", ".join(waiting)} to reach '
                                   'their readers', throttle_duration_sec=5.0)
            return False
        for topic, count in self._wait_for.items():
            # Own publishers: readers actually matched to them (the graph's counts can run
            # ahead of endpoint matching). Other topics: what discovery reports.
            own = {topics.ODOM: self.odom_pub, topics.ODOM_TRUTH: self.truth_pub,
                   topics.CLOCK: self.clock_pub}.get(topic)
            seen = own.get_subscription_count() if own else self.count_subscribers(topic)
            if seen < count:
                return False
        return all(self.count_publishers(ACK_TOPICS[key][0]) >= 1 for key in self.config.acks)

    def _try_start(self) -> None:
        if not self._graph_ready():
            self._ready_since = None
            return
        now = time.monotonic()
        if self._ready_since is None:
            self._ready_since = now
        if now - self._ready_since < self.config.settle_s:
            return
        self._start_timer.cancel()
        self.started = True
        self.wall_start = time.monotonic()
        self.publish_state()
        if self.config.speed > 0.0:
            self.create_timer(self.sim.dt_ns * 1e-9 / self.config.speed, self.advance)
        else:
            self.create_timer(self.config.resend_period_s, self._resend_if_stalled)

    def _pause(self, _msg: Empty) -> None:
        """The mission is over: stop stepping.

        The node stays up, so that every reader can still take (and have resent) the
        last steps.
        """
        self.sim.paused = True

    def advance(self) -> None:
        """One exact zero-order-hold step with the held force and disturbance."""
        if self.sim.advance():
            self.publish_state()

    def publish_state(self) -> None:
        now = self.sim.now_ns
        truth = conv.odometry_msg(now, self.sim.x)
        # One measurement per step (a resend repeats it), so a run's noise is its seed's.
        measured = truth if self.noise.exact else conv.odometry_msg(
            now, self.noise.measure(self.sim.x), self.noise.position_variance,
            self.noise.velocity_variance)
        self._last_odometry = truth, measured
        if self.contact_pub is not None and self.sim.contact:
            assert isinstance(self.sim.plant, MujocoPlant)
            self.contact_pub.publish(plant_contact_msg(now, self.sim.contact,
                                                       self.sim.plant.contact_steps))
        self.clock_pub.publish(conv.clock_msg(now))
        self._publish_odometry()

    def _publish_odometry(self) -> None:
        assert self._last_odometry is not None
        truth, measured = self._last_odometry
        self.truth_pub.publish(truth)
        self.odom_pub.publish(measured)
        self._last_publish = time.monotonic()

    def _resend_if_stalled(self) -> None:
        if self.sim.finished or time.monotonic() - self._last_publish < self.config.resend_period_s:
            return
        missing = ', '.join(sorted(self.gate.missing(self.sim.now_ns)))
        self.get_logger().warning(
            f'step {self.sim.step_index}: no acknowledgement from {missing} for '
            f'{self.config.resend_period_s:.1f} s; republishing odometry')
        self._publish_odometry()


def main(args: list[str] | None = None) -> None:
    spin_node(SimulatorNode, args)


if __name__ == '__main__':
    main()
