"""Safety node: kinodynamic margin, augmented obstacles, true clearance (RRT-QX §2, §5).

Each step: D_rob of the robot from its current leg (from the controller's state of the
step before), its running maximum, and — when that maximum has grown or the detected
set changed — every detected obstacle grown by max D_rob + robot radius, published on
/obstacles/augmented (latched) so that the planner repairs its graph. It also watches
the clearance to the true obstacles of the scenario and flags a collision the moment
it happens; /safety/status goes out every step.
"""

from __future__ import annotations

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState, ObstacleArray, PerceptionStatus, SafetyStatus

from rrtq_planner.safety import SafetyConfig, SafetyMonitor, clearance
from rrtq_sim import conversions as conv
from rrtq_sim import qos, topics
from rrtq_sim.lockstep import Requirement, StepInputs, seconds_to_ns
from rrtq_sim.params import declare, spin_node
from rrtq_sim.perception import TrueObstacles
from rrtq_sim.polygon_set import LivePolygons, PolygonSet
from rrtq_sim.scenario import load_scenario


class SafetyNode(Node):
    """Grows the detected obstacles by the robot's measured deviation from its legs."""

    def __init__(self, **kwargs) -> None:
        super().__init__('safety', **kwargs)
        d = lambda *a, **k: declare(self, *a, **k)  # noqa: E731
        scenario = load_scenario(d('scenario', '', 'scenario YAML (true obstacles, robot '
                                   'radius)'))
        self.truth = TrueObstacles.for_scenario(scenario)
        self.robot_radius = scenario.robot_radius
        self.monitor = SafetyMonitor(SafetyConfig(
            robot_radius=scenario.robot_radius,
            growth_threshold=d('growth_threshold', 0.05, 'republish the augmented set when '
                               'the margin has grown by this much, m', low=0.0)))
        dt = d('dt', 0.05, 'step of the simulation, s', low=1e-4)
        chain = d('chain', [''], "lock-step inputs awaited per step: 'perception_status', "
                  "'controller_state' (empty: paced)", element=str)
        self.lockstep = any(chain)
        requirements = []
        if 'perception_status' in chain:
            requirements.append(Requirement('perception', followup='detected',
                                            names=lambda m: conv.stamp_ns(m.detected_stamp)))
        if 'controller_state' in chain:
            requirements.append(Requirement('state', lag=1))
        self.inputs = StepInputs(requirements, seconds_to_ns(dt))
        self.latest: dict[str, object] = {}
        self.detected_stamp = -1
        self.detected: list[tuple[str, np.ndarray]] = []
        self.published: list[tuple[str, np.ndarray]] = []
        self.published_shapes = PolygonSet([])
        self.existing_shapes = LivePolygons()
        self.augmented_stamp = 0
        self.collided = False
        self.last: SafetyStatus | None = None
        self.aug_pub = self.create_publisher(ObstacleArray, topics.OBSTACLES_AUGMENTED,
                                             qos.LATCHED)
        self.status_pub = self.create_publisher(SafetyStatus, topics.SAFETY_STATUS, qos.STREAM)
        self.create_subscription(Odometry, topics.ODOM, self._filer('odom'), qos.STREAM)
        self.create_subscription(ObstacleArray, topics.OBSTACLES_DETECTED,
                                 self._filer('detected'), qos.LATCHED)
        self.create_subscription(PerceptionStatus, topics.PERCEPTION_STATUS,
                                 self._filer('perception'), qos.STREAM)
        self.create_subscription(ControllerState, topics.CONTROLLER_STATE, self._filer('state'),
                                 qos.STREAM)

    def _filer(self, key: str):
        def callback(msg) -> None:
            stamp = conv.stamp_ns(msg.header.stamp)
            if key == 'odom' and self.last is not None \
                    and stamp <= conv.stamp_ns(self.last.header.stamp):
                self.status_pub.publish(self.last)   # a resent step: answer it again
                return
            if not self.lockstep:
                self.latest[key] = msg
                if key == 'odom':
                    self.step(stamp, msg, self.latest.get('detected'), self.latest.get('state'))
                return
            self.inputs.add(key, stamp, msg)
            for step in self.inputs.pop_ready():
                self.step(step['stamp_ns'], step['odom'], step.get('detected'),
                          step.get('state'))
        return callback

    def step(self, stamp: int, odom: Odometry, detected: ObstacleArray | None,
             state: ControllerState | None) -> None:
        position = conv.odometry_state(odom)[:2]
        t = stamp * 1e-9
        changed = False
        if detected is not None and conv.stamp_ns(detected.header.stamp) != self.detected_stamp:
            self.detected_stamp = conv.stamp_ns(detected.header.stamp)
            self.detected = conv.obstacle_array(detected)
            changed = True
        grown = False
        leg_index = 0
        if state is not None and state.d0 > 0.0:
            leg_index = state.leg_index
            grown = self.monitor.update([state.leg_start.x, state.leg_start.y],
                                        [state.leg_target.x, state.leg_target.y], position)
        swallowed = self.published_shapes.nearest(position)[0] < 0.0
        if changed or grown or swallowed or self.monitor.published_margin is None:
            self.augmented_stamp = stamp
            self.published = self.monitor.augmented(self.detected, position)
            self.published_shapes = PolygonSet([poly for _, poly in self.published])
            self.aug_pub.publish(conv.obstacle_array_msg(stamp, self.published,
                                                         self.monitor.margin))
        existing = self.truth.update(position, t)
        gap, index = clearance(position, self.existing_shapes.update(existing),
                               self.robot_radius)
        if gap < 0.0 and not self.collided:
            self.collided = True
            self.get_logger().error(f'collision with {existing[index].id} at t={t:.2f} s, '
                                    f'({position[0]:.2f}, {position[1]:.2f})')
        status = SafetyStatus(
            d_rob=self.monitor.d_rob, d_rob_max=self.monitor.d_rob_max,
            margin=self.monitor.margin, min_clearance=float(gap),
            nearest_obstacle=existing[index].id if index >= 0 else '', collision=self.collided,
            leg_index=leg_index, augmented_stamp=conv.time_msg(self.augmented_stamp))
        status.header = odom.header
        self.last = status
        self.status_pub.publish(status)


def main(args: list[str] | None = None) -> None:
    spin_node(SafetyNode, args)


if __name__ == '__main__':
    main()
