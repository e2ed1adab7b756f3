"""Supervisor node: watches the run for the orchestrator and publishes the goal."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rrtq_msgs.msg import ControllerState, PlannerStats, PlantContact
from std_msgs.msg import Empty

from rrtq_bringup.mission import MissionMonitor
from rrtq_common import conversions as conv
from rrtq_common import qos, topics
from rrtq_common.executors import NODE_OPTIONS


class SupervisorNode(Node):
    """Feeds the mission monitor from /odom/truth, /cmd_force, /controller/state, /planner/stats.

    The referee judges the true state, never the robot's measurement (/odom); ``rrtq robot``,
    which has no truth, judges its mission from ``odometry`` = /odom.
    """

    def __init__(self, monitor: MissionMonitor, goal: np.ndarray,
                 odometry: str = topics.ODOM_TRUTH, **kwargs) -> None:
        super().__init__('supervisor', **NODE_OPTIONS, **kwargs)
        self.monitor = monitor
        self.goal_pub = self.create_publisher(PoseStamped, topics.GOAL_POSE, qos.LATCHED)
        goal_msg = PoseStamped()
        goal_msg.header.frame_id = conv.MAP_FRAME
        goal_msg.pose.position.x, goal_msg.pose.position.y = float(goal[0]), float(goal[1])
        goal_msg.pose.orientation.w = 1.0
        self.goal_pub.publish(goal_msg)
        self.pause_pub = self.create_publisher(Empty, topics.SIMULATOR_PAUSE, qos.LATCHED)
        self.last_odom_ns = -1
        # The true odometry as bytes, read as the step's nodes read /odom (rrtq_common.inputs).
        self.create_subscription(Odometry, odometry, self.on_odom_bytes, qos.STREAM, raw=True)
        self.create_subscription(WrenchStamped, topics.CMD_FORCE, self.on_cmd, qos.STREAM)
        self.create_subscription(ControllerState, topics.CONTROLLER_STATE, self.on_state,
                                 qos.STREAM)
        self.create_subscription(PlannerStats, topics.PLANNER_STATS, self.on_stats, qos.STREAM)
        # The physics plant's contacts (plant.model: mujoco): a collision the simulator felt.
        self.create_subscription(PlantContact, topics.PLANT_CONTACT, self.on_contact, qos.STREAM)

    def on_odom_bytes(self, data: bytes) -> None:
        self.on_odom(conv.read_odometry(data))

    def on_odom(self, msg: Odometry | conv.OdometryReading) -> None:
        stamp = conv.stamp_ns(msg.header.stamp)
        if stamp <= self.last_odom_ns:
            return
        self.last_odom_ns = stamp
        self.monitor.on_odometry(stamp * 1e-9, conv.odometry_state(msg)[:2])

    def pause_simulation(self) -> None:
        """Ask the simulator to stop stepping (the mission is over)."""
        self.pause_pub.publish(Empty())

    def on_cmd(self, msg: WrenchStamped) -> None:
        self.monitor.on_command(conv.stamp_ns(msg.header.stamp) * 1e-9,
                                np.array([msg.wrench.force.x, msg.wrench.force.y]))

    def on_state(self, msg: ControllerState) -> None:
        self.monitor.controller_step_ms.append(msg.step_ms)

    def on_contact(self, msg: PlantContact) -> None:
        self.monitor.on_contact(conv.stamp_ns(msg.header.stamp) * 1e-9, tuple(msg.obstacles),
                                msg.contact_steps)

    def on_stats(self, msg: PlannerStats) -> None:
        self.monitor.on_plan_status(conv.stamp_ns(msg.header.stamp) * 1e-9,
                                    msg.status == PlannerStats.STATUS_FOUND)
        if msg.replans > self.monitor.replans:
            self.monitor.replans = msg.replans
            self.monitor.replan_ms.append(msg.last_repair_ms)
