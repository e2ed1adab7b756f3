"""Scenario files (YAML): the schema, its strict reading, the builders of its cores.

The contract is docs/design.md's "Scenario contract"; ``docs/scenarios.md`` documents every key.
"""

from rrtq_bringup.scenario.loader import (build_disturbance, build_plant, game_riccati,
                                          load_scenario, parse_scenario, worst_case_game)
from rrtq_bringup.scenario.schema import Scenario
from rrtq_common.world import ObstacleSpec
from rrtq_common.yaml_reader import ScenarioError

__all__ = [
    'ScenarioError', 'ObstacleSpec', 'Scenario', 'load_scenario', 'parse_scenario', 'build_plant', 'worst_case_game',
    'game_riccati', 'build_disturbance',
]
