"""A run's recording as numpy series: everything the report needs, from the MCAP alone.

Decoding uses ``mcap_ros2``'s decoder (the schema text in the file, not the installed
message packages), so a recording can be read on a machine without this workspace.
"""

from __future__ import annotations

import dataclasses
from typing import Any
import pathlib

import numpy as np
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rrtq_bringup.recording import SCENARIO_METADATA
from rrtq_bringup.scenario import Scenario, parse_scenario


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _polygons(msg) -> list[tuple[str, np.ndarray]]:
    return [(o.id, np.array([[p.x, p.y] for p in o.polygon.points]).reshape(-1, 2))
            for o in msg.obstacles]


def messages(path: str | pathlib.Path, topic: str) -> list[Any]:
    """Every message of ``topic`` in the recording, decoded, in log-time order."""
    factory = DecoderFactory()
    with open(path, 'rb') as f:
        return [factory.decoder_for(c.message_encoding, s)(m.data) for s, c, m in
                make_reader(f).iter_messages(topics=[topic], log_time_order=True)]


@dataclasses.dataclass(frozen=True)
class SafetyLeg:
    """One leg as ``/safety/status`` reports it (the recording's one reading of its legs)."""

    index: int
    """The status field that numbers it (``legs`` by default: the legs measured so far, the
    current one included; or the controller's ``leg_index``)."""
    start: float
    """s: the stamp of its first status."""
    margin: float
    """m: ``leg_margin`` at its first status, the margin in force at its start."""
    tube: float
    """m: ``leg_tube``, the tube learned_bound predicted at its start (0: none or another mode)."""
    scale: float
    """The calibrated scale at its start (1: uncalibrated)."""
    refuted: bool | None
    """Whether the tube rested on a level residuals raised (None: a recording older than it)."""
    deviation: float
    """m: ``leg_deviation`` at its last status, its largest deviation."""
    least_margin: float
    """m: the least ``margin`` published while it ran."""


def safety_legs(statuses: list[Any], by: str = 'legs') -> list[SafetyLeg]:
    """The legs of a run's ``/safety/status`` messages, in order.

    Statuses before the first leg (``legs`` = 0) belong to none. ``by``: the field that
    numbers them.
    """
    legs: dict[int, SafetyLeg] = {}
    for s in statuses:
        if s.legs == 0:
            continue
        key = int(getattr(s, by))
        leg = legs.get(key)
        if leg is None:
            leg = SafetyLeg(key, _stamp(s.header), float(s.leg_margin), float(s.leg_tube),
                            float(s.scale), getattr(s, 'leg_refuted', None),
                            float(s.leg_deviation), float(s.margin))
        legs[key] = dataclasses.replace(leg, deviation=float(s.leg_deviation),
                                        least_margin=min(leg.least_margin, float(s.margin)))
    return [legs[k] for k in sorted(legs)]


@dataclasses.dataclass
class RunData:
    """Time series and snapshots of one run (times in s of sim time)."""

    odom_t: np.ndarray                 # (N,)
    odom_x: np.ndarray                 # (N, 4): p_x, p_y, v_x, v_y
    cmd_t: np.ndarray
    cmd_u: np.ndarray                  # (N, 2) N
    dist_t: np.ndarray
    dist_d: np.ndarray                 # (N, q)
    state_t: np.ndarray
    leg_index: np.ndarray
    leg_target: np.ndarray             # (N, 2)
    d0: np.ndarray
    d: np.ndarray
    critic_w: list[np.ndarray]
    actor_w: list[np.ndarray]
    disturbance_w: list[np.ndarray]
    safety_t: np.ndarray
    d_rob: np.ndarray
    d_rob_max: np.ndarray
    clearance: np.ndarray
    truth: list[tuple[float, list[tuple[str, np.ndarray]]]]      # every published set
    detected: list[tuple[float, list[tuple[str, np.ndarray]]]]
    augmented: list[tuple[float, list[tuple[str, np.ndarray]]]]
    plans: list[tuple[float, np.ndarray]]                        # (t, (K, 2) path)
    tree_segments: np.ndarray | None                             # last tree: (E, 2, 2)
    goal: np.ndarray | None
    topics: dict[str, int]
    time_rates: list[float] = dataclasses.field(default_factory=list)   # controller's basis
    time_powers: list[float] = dataclasses.field(default_factory=list)
    force_limit: float = float('inf')        # the controller's actuator limit, N per axis
    policy_events: list[tuple[float, str, str]] = dataclasses.field(default_factory=list)
    """(t, event, reason) of every step the guard of safe learning acted at."""
    states: list[Any] = dataclasses.field(default_factory=list)   # /controller/state, in time
    true_t: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    true_x: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 4)))
    """/odom/truth, the simulator's true state (N, 4); empty in a recording made before it
    existed, whose /odom was the true state."""

    def true_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(t, x) of the true state: /odom/truth when recorded, else /odom.

        /odom is what the robot measured (with the scenario's odometry noise); a recording
        without /odom/truth comes from before the noise, when /odom was the true state.
        """
        if self.true_t.size:
            return self.true_t, self.true_x
        return self.odom_t, self.odom_x


# Topics read_run decodes; every other topic is only counted.
_DECODED = frozenset((
    '/odom', '/odom/truth', '/cmd_force', '/disturbance', '/controller/state', '/safety/status',
    '/obstacles/truth', '/obstacles/detected', '/obstacles/augmented', '/plan', '/goal_pose'))


def read_run(path: str | pathlib.Path) -> RunData:
    """Decode every message of the topics the report uses (of /planner/tree, the last)."""
    series: dict[str, list] = {k: [] for k in (
        'odom', 'true', 'cmd', 'dist', 'state', 'safety', 'truth', 'detected', 'augmented', 'plan')}
    last_tree = None
    goal = None
    topics: dict[str, int] = {}
    factory = DecoderFactory()

    def decode(schema, channel, raw):
        return factory.decoder_for(channel.message_encoding, schema)(raw.data)

    with open(path, 'rb') as f:
        for schema, channel, raw in make_reader(f).iter_messages(log_time_order=True):
            topic = channel.topic
            topics[topic] = topics.get(topic, 0) + 1
            if topic == '/planner/tree':     # thousands of points each: decode the last only
                last_tree = schema, channel, raw
            if topic not in _DECODED:
                continue
            msg = decode(schema, channel, raw)
            if topic in ('/odom', '/odom/truth'):
                p, v = msg.pose.pose.position, msg.twist.twist.linear
                series['odom' if topic == '/odom' else 'true'].append(
                    (_stamp(msg.header), [p.x, p.y, v.x, v.y]))
            elif topic == '/cmd_force':
                series['cmd'].append((_stamp(msg.header), [msg.wrench.force.x,
                                                           msg.wrench.force.y]))
            elif topic == '/disturbance':
                series['dist'].append((_stamp(msg.header), list(msg.value)))
            elif topic == '/controller/state':
                series['state'].append(msg)
            elif topic == '/safety/status':
                series['safety'].append(msg)
            elif topic in ('/obstacles/truth', '/obstacles/detected', '/obstacles/augmented'):
                series[topic.rsplit('/', 1)[1]].append((_stamp(msg.header), _polygons(msg)))
            elif topic == '/plan':
                series['plan'].append((_stamp(msg.header), np.array(
                    [[p.pose.position.x, p.pose.position.y] for p in msg.poses]).reshape(-1, 2)))
            elif topic == '/goal_pose':
                goal = np.array([msg.pose.position.x, msg.pose.position.y])
    tree = None if last_tree is None else decode(*last_tree)

    def arrays(key: str, width: int) -> tuple[np.ndarray, np.ndarray]:
        rows = sorted(series[key], key=lambda r: r[0])
        if not rows:
            return np.zeros(0), np.zeros((0, width))
        return (np.array([r[0] for r in rows]),
                np.array([r[1] for r in rows], dtype=float).reshape(len(rows), -1))

    odom_t, odom_x = arrays('odom', 4)
    true_t, true_x = arrays('true', 4)
    cmd_t, cmd_u = arrays('cmd', 2)
    dist_t, dist_d = arrays('dist', 1)
    states = sorted(series['state'], key=lambda m: _stamp(m.header))
    safety = sorted(series['safety'], key=lambda m: _stamp(m.header))
    return RunData(
        odom_t=odom_t, odom_x=odom_x, cmd_t=cmd_t, cmd_u=cmd_u, dist_t=dist_t, dist_d=dist_d,
        state_t=np.array([_stamp(m.header) for m in states]),
        leg_index=np.array([m.leg_index for m in states], dtype=int),
        leg_target=np.array([[m.leg_target.x, m.leg_target.y] for m in states]).reshape(-1, 2),
        d0=np.array([m.d0 for m in states]), d=np.array([m.d for m in states]),
        critic_w=[np.asarray(m.critic_weights) for m in states],
        actor_w=[np.asarray(m.actor_weights) for m in states],
        disturbance_w=[np.asarray(m.disturbance_weights) for m in states],
        safety_t=np.array([_stamp(m.header) for m in safety]),
        d_rob=np.array([m.d_rob for m in safety]),
        d_rob_max=np.array([m.d_rob_max for m in safety]),
        clearance=np.array([m.min_clearance for m in safety]),
        truth=series['truth'], detected=series['detected'], augmented=series['augmented'],
        plans=series['plan'], tree_segments=_tree_segments(tree), goal=goal, topics=topics,
        time_rates=list(getattr(states[-1], 'time_rates', [])) if states else [],
        time_powers=list(getattr(states[-1], 'time_powers', [])) if states else [],
        force_limit=float(getattr(states[-1], 'force_limit', 0.0) or float('inf')) if states else float('inf'),
        policy_events=[(_stamp(m.header), e, r) for m in states
                       if getattr(m, 'policy_event', '')
                       for e, r in zip(m.policy_event.split(';'), m.policy_reason.split('; '))],
        states=states, true_t=true_t, true_x=true_x)


def _tree_segments(msg) -> np.ndarray | None:
    """Line-list markers of the last /planner/tree message as (E, 2, 2) segments."""
    if msg is None:
        return None
    points = [[p.x, p.y] for marker in msg.markers if marker.type == 5   # LINE_LIST
              for p in marker.points]
    return np.array(points, dtype=float).reshape(-1, 2, 2)


def embedded_scenario(path: str | pathlib.Path) -> dict:
    """The scenario YAML the recorder embedded as MCAP metadata ({} if absent)."""
    with open(path, 'rb') as f:
        for record in make_reader(f).iter_metadata():
            if record.name == SCENARIO_METADATA:
                return yaml.safe_load(record.metadata['yaml']) or {}
    return {}


def recorded_scenario(path: str | pathlib.Path) -> Scenario:
    """The embedded scenario, parsed (plant, controller, bounds...), without its obstacles.

    An obstacle file is named relative to the scenario file, which need not be beside the
    recording; the obstacles that mattered are in the recording (/obstacles/truth).
    """
    return parse_scenario({**embedded_scenario(path), 'obstacles': []}, str(path))
