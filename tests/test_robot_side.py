"""No simulator truth on the robot's side: what the planner, controller and safety node hear.

The robot's nodes are built from the graph of a scenario (their parameters as a run gives
them) on an in-process executor, after the scenario file is gone: whatever they know, they
got from their parameters, not from the file whose obstacles are the truth. The ROS graph
then says which topics each one subscribes to.
"""

import importlib
import types

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter

from rrtq_bringup.graph import build_graph
from rrtq_bringup.scenario import load_scenario
from rrtq_bringup.testing import spin_until
from rrtq_common import topics
from rrtq_common.world import ObstacleSpec, TrueObstacles

ROBOT_NODES = ('planner', 'controller', 'safety')
SIMULATOR_TRUTH = {topics.ODOM_TRUTH, topics.OBSTACLES_TRUTH, topics.REFEREE_STATUS}

SCENARIO = """
name: robot-side
bounds: {{x: [-10, 10], y: [-10, 10]}}
start: [-6.0, -6.0]
goal: [6.0, 5.0]
{controller}
obstacles:
  - {{id: box, polygon: [[-1, -3], [1, -3], [1, 3], [-1, 3]]}}
  - {{id: late, circle: {{center: [3, 3], radius: 1.0}}, appear_at: 2.0}}
"""


def _holds_truth(obj, seen, depth=0):
    """Whether ``obj`` reaches an ObstacleSpec or a TrueObstacles through its attributes."""
    if id(obj) in seen or depth > 8 or isinstance(obj, (str, bytes, int, float, np.ndarray,
                                                         types.ModuleType, type)):
        return False
    seen.add(id(obj))
    if isinstance(obj, (ObstacleSpec, TrueObstacles)):
        return True
    if isinstance(obj, dict):
        children = list(obj.keys()) + list(obj.values())
    elif isinstance(obj, (list, tuple, set, frozenset)):
        children = list(obj)
    else:
        children = list(getattr(obj, '__dict__', {}).values())
    return any(_holds_truth(child, seen, depth + 1) for child in children)


@pytest.mark.parametrize('controller', ['controller: {measured_disturbance: false}', ''],
                         ids=['measured_disturbance_false', 'defaults'])
def test_the_robot_nodes_hear_no_simulator_truth(ros, tmp_path, controller):
    context, executor, _ = ros
    path = tmp_path / 'scenario.yaml'
    path.write_text(SCENARIO.format(controller=controller))
    scenario = load_scenario(path)
    specs = {s.name: s for s in build_graph(scenario, 0.0, str(tmp_path / 'run.mcap'))}
    path.unlink()                   # the truth is not there to be read
    nodes = {}
    for name in ROBOT_NODES:
        spec = specs[name]
        assert 'scenario' not in spec.params, name
        cls = getattr(importlib.import_module(spec.module), spec.cls)
        nodes[name] = cls(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in spec.params.items()])
        executor.add_node(nodes[name])
    probe = rclpy.create_node('probe', context=context)
    executor.add_node(probe)

    def heard(name):
        return {topic for topic, _ in probe.get_subscriber_names_and_types_by_node(name, '/')}
    # Discovery is done once every node is seen subscribing to /odom, which each reads.
    assert spin_until(executor, lambda: all(topics.ODOM in heard(n) for n in ROBOT_NODES), 20.0)
    reads_disturbance = scenario.controller.reads_disturbance
    for name in ROBOT_NODES:
        subscribed = heard(name)
        assert not subscribed & SIMULATOR_TRUTH, (name, sorted(subscribed & SIMULATOR_TRUTH))
        expected = name == 'controller' and reads_disturbance
        assert (topics.DISTURBANCE in subscribed) == expected, (name, sorted(subscribed))
        assert set(specs[name].subscribes) <= subscribed, name
    # The safety node got the bounds and the robot's radius, not the obstacles.
    safety = nodes['safety']
    assert safety.monitor.config.robot_radius == scenario.robot_radius
    assert safety.monitor.config.region == scenario.bounds
    for name, node in nodes.items():
        assert not _holds_truth(node, set()), name
