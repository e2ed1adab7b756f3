"""Safety node: kinodynamic margin, augmented obstacles, true clearance (RRT-QX §2, §5).

Each step (:meth:`rrtq_planner.safety.SafetyMonitor.step`): D_rob of the robot from its
current leg (from the controller's state of the step before), its running maximum, and —
when that maximum has grown or the detected set changed — every detected obstacle grown
by max D_rob + robot radius, published on /obstacles/augmented (latched) so that the
planner repairs its graph. It also watches the clearance to the true obstacles of the
scenario and flags a collision the moment it happens; /safety/status goes out every step.
"""

from __future__ import annotations

from typing import Any

from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState, ObstacleArray, PerceptionStatus, SafetyStatus

from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS
from rrtq_common.inputs import Input, subscribe_inputs
from rrtq_common.lockstep import Requirement, Step, StepGate, seconds_to_ns
from rrtq_common.params import declare_config, spin_node
from rrtq_common.run import RunConfig
from rrtq_common.world import TrueObstacles
from rrtq_common.world_yaml import WorldSource, load_world
from rrtq_planner.conversions import leg_of, safety_status_msg
from rrtq_planner.safety import SafetyConfig, SafetyMonitor


class SafetyNode(Node):
    """Grows the detected obstacles by the robot's measured deviation from its legs."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('safety', **NODE_OPTIONS, **kwargs)
        world = load_world(declare_config(self, WorldSource).scenario)
        run = declare_config(self, RunConfig, exclude=('seed',))
        config = declare_config(self, SafetyConfig, robot_radius=world.robot_radius)
        self.monitor = SafetyMonitor(config, TrueObstacles.for_scenario(world))
        self.aug_pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_AUGMENTED,
                                             qos.LATCHED)
        self.status_pub = self.create_publisher(SafetyStatus, topics.SAFETY_STATUS, qos.STREAM)
        self.gate = StepGate(
            [Requirement('perception', followup='detected',
                         names=lambda m: conv.stamp_ns(m.detected_stamp)),
             Requirement('state', lag=1)],
            lockstep=run.lockstep, dt_ns=seconds_to_ns(run.dt), resend=self.status_pub.publish,
            on_step=self.step)
        subscribe_inputs(self, self.gate, (
            Input('odom', Odometry, topics.ODOM, qos.STREAM),
            Input('detected', ObstacleArray, topics.OBSTACLES_DETECTED, qos.LATCHED),
            Input('perception', PerceptionStatus, topics.PERCEPTION_STATUS, qos.STREAM),
            Input('state', ControllerState, topics.CONTROLLER_STATE, qos.STREAM)))

    def step(self, step: Step) -> None:
        odom, detected = step['odom'], step.get('detected')
        position = conv.odometry_state(odom)[:2]
        done = self.monitor.step(step.stamp_ns, position, conv.changed_obstacles(detected),
                                 leg_of(step.get('state')))
        if done.augmented is not None:
            self.aug_pub.publish(conv.obstacle_array_msg(step.stamp_ns, done.augmented,
                                                         done.margin))
        if done.new_collision:
            self.get_logger().error(f'collision with {done.nearest} at t={step.stamp_ns * 1e-9:.2f}'
                                    f' s, ({position[0]:.2f}, {position[1]:.2f})')
        status = safety_status_msg(odom.header, done)
        self.gate.answered(step.stamp_ns, status)
        self.status_pub.publish(status)


def main(args: list[str] | None = None) -> None:
    spin_node(SafetyNode, args)


if __name__ == '__main__':
    main()
