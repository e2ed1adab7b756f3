"""The start-up handshake (rrtq_common.readiness): no first step before every writer's readers."""

import dataclasses
import pathlib

import pytest
import rclpy
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from std_msgs.msg import String

from rrtq_bringup.graph import STEP_TOPICS, build_graph
from rrtq_bringup.scenario import load_scenario
from rrtq_bringup.testing import Collector, spin_until
from rrtq_common import qos, readiness, topics
from rrtq_sim.simulator_node import SimulatorNode

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_a_node_announces_only_once_its_writer_has_matched_every_reader(ros):
    context, executor, _ = ros
    writer = rclpy.create_node('writer', context=context, parameter_overrides=[
        Parameter(readiness.PARAMETER, value=['/cmd_force:2'])])
    pub = writer.create_publisher(WrenchStamped, '/cmd_force', qos.STREAM)
    announcer = readiness.announce_when_matched(writer)
    assert announcer is not None
    listener = rclpy.create_node('listener', context=context)
    ready = Collector(listener, String, topics.GRAPH_READY, readiness.QOS)
    for node in (writer, listener):
        executor.add_node(node)
    spin_until(executor, lambda: False, 1.0)
    assert len(ready) == 0 and announcer.missing() == {'/cmd_force': 0}
    first = listener.create_subscription(WrenchStamped, '/cmd_force', lambda _: None, qos.STREAM)
    assert spin_until(executor, lambda: pub.get_subscription_count() == 1, 10.0)
    spin_until(executor, lambda: False, 0.5)
    assert len(ready) == 0 and announcer.missing() == {'/cmd_force': 1}
    second = rclpy.create_node('second', context=context)
    second.create_subscription(WrenchStamped, '/cmd_force', lambda _: None, qos.STREAM)
    executor.add_node(second)
    assert spin_until(executor, lambda: len(ready) == 1, 10.0)
    assert ready.messages[0].data == 'writer' and pub.get_subscription_count() == 2
    spin_until(executor, lambda: False, 0.3)
    assert len(ready) == 1                      # once
    assert first is not None


def test_a_node_without_the_parameter_announces_nothing(ros):
    context, _, _ = ros
    node = rclpy.create_node('plain', context=context)
    assert readiness.announce_when_matched(node) is None
    node.destroy_node()


def test_a_malformed_expectation_is_refused():
    with pytest.raises(ValueError, match='ready_when_matched'):
        readiness.expectations(['/cmd_force'])
    assert readiness.expectations(['/a/b:3', '/c:0']) == {'/a/b': 3, '/c': 0}


def test_the_simulator_takes_no_step_before_the_nodes_it_awaits_announce(ros):
    context, executor, _ = ros
    sim = SimulatorNode(context=context, parameter_overrides=[
        Parameter('A', value=[0.0] * 16), Parameter('B', value=[0.0] * 8),
        Parameter('F', value=[0.0] * 4), Parameter('dt', value=0.05),
        Parameter('acks', value=['cmd_force']), Parameter('wait_for', value=['/odom:1']),
        Parameter('ready_from', value=['controller', 'disturbance_injector']),
        Parameter('settle_s', value=0.0)])
    peer = rclpy.create_node('peer', context=context)
    odoms = Collector(peer, Odometry, topics.ODOM, qos.STREAM)
    peer.create_publisher(WrenchStamped, topics.CMD_FORCE, qos.STREAM)
    announce = peer.create_publisher(String, topics.GRAPH_READY, readiness.QOS)
    for node in (sim, peer):
        executor.add_node(node)
    announce.publish(String(data='controller'))
    spin_until(executor, lambda: False, 1.5)
    assert not sim.started and len(odoms) == 0
    announce.publish(String(data='disturbance_injector'))
    assert spin_until(executor, lambda: len(odoms) == 1, 10.0)
    assert sim.started


def test_the_graph_gives_each_writer_its_readers_and_the_simulator_their_names(tmp_path):
    scenario = load_scenario(str(ROOT / 'scenarios' / 'rrtqx_paper.yaml'))
    specs = {s.name: s for s in build_graph(scenario, 0.0, str(tmp_path / 'r.mcap'))}
    sim = specs['simulator'].params
    writers = {name: s for name, s in specs.items() if readiness.PARAMETER in s.params}
    assert sorted(sim['ready_from']) == sorted(writers) == sorted(
        ['controller', 'disturbance_injector', 'obstacle_spawner', 'planner', 'safety'])
    written = {}
    for name, spec in writers.items():
        for topic, count in readiness.expectations(spec.params[readiness.PARAMETER]).items():
            written[topic] = count
            # Every node that reads it, and the simulator for what it holds.
            readers = [n for n, s in specs.items() if topic in s.subscribes]
            assert count == len(readers) and 'recorder' in readers, (name, topic)
    # Each per-step topic: the simulator's own by matched counts, the others announced.
    assert set(written) | {topics.CLOCK, topics.ODOM, topics.ODOM_TRUTH} == set(STEP_TOPICS)


def test_the_nominal_controller_reads_the_disturbance_only_when_told_to(tmp_path):
    """By default the robot side is blind to /disturbance (no robot has it); with
    ``measured_disturbance: true`` (a robot with a sensor of it) the critic learns from it:
    it subscribes, and the injector waits for it too."""
    scenario = load_scenario(str(ROOT / 'scenarios' / 'rrtqx_paper.yaml'))
    assert not scenario.controller.measured_disturbance
    reads = dataclasses.replace(scenario, controller=dataclasses.replace(
        scenario.controller, measured_disturbance=True))
    counts = {}
    for name, s in (('reads', reads), ('blind', scenario)):
        specs = {spec.name: spec for spec in build_graph(s, 0.0, str(tmp_path / f'{name}.mcap'))}
        counts[name] = readiness.expectations(
            specs['disturbance_injector'].params[readiness.PARAMETER])[topics.DISTURBANCE]
        assert (topics.DISTURBANCE in specs['controller'].subscribes) == (name == 'reads')
    assert counts['reads'] == counts['blind'] + 1
