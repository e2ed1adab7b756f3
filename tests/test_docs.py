"""The documents stay true to the code: the modules they name exist, topics and messages match, the
example loads (their links: test_docs_links.py)."""

from __future__ import annotations

import importlib
import pathlib
import re
import shutil

from rrtq_bringup.scenario import load_scenario
from rrtq_common import topics
from rrtq_testing.paths import OTTE

ROOT = pathlib.Path(__file__).resolve().parents[1]
DESIGN = ROOT / 'docs' / 'design.md'
DOCUMENTS = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md')),
             ROOT / 'scenarios' / 'envs' / 'README.md',
             OTTE / 'README.md']


DOTTED = re.compile(r'\b(rrtq_[a-z_]+(?:\.[A-Za-z_]\w*)+)')


def _resolves(name: str) -> bool:
    """``rrtq_pkg.module[.attribute...]`` names an importable module and its attributes."""
    parts = name.split('.')
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_every_module_the_documents_name_exists():
    stale = [f'{doc.name}: {name}' for doc in DOCUMENTS
             for name in sorted(set(DOTTED.findall(doc.read_text()))) if not _resolves(name)]
    assert not stale, stale


def test_the_name_check_tells_a_stale_name():
    assert _resolves('rrtq_common.lockstep.StepGate') and _resolves('rrtq_planner.safety')
    assert not _resolves('rrtq_sim.lockstep.StepInputs')     # moved to rrtq_common
    assert not _resolves('rrtq_planner.safety.NoSuchThing')


def _section(text: str, title: str) -> str:
    start = text.index(f'\n## {title}\n')
    end = text.find('\n## ', start + 1)
    return text[start:end if end > 0 else None]


def test_the_topic_table_is_the_graphs_topics():
    table = _section(DESIGN.read_text(), 'Node graph and topics')
    documented = set(re.findall(r'^\| `(/[a-z_/]+)` \|', table, flags=re.M))
    defined = {v for k, v in vars(topics).items() if k.isupper() and isinstance(v, str)}
    assert documented == defined | {'/rosout'}


def test_every_message_field_is_documented():
    text = DESIGN.read_text()
    for msg in sorted((ROOT / 'ros2_ws' / 'src' / 'rrtq_msgs' / 'msg').glob('*.msg')):
        assert f'`{msg.stem}`' in text, msg.stem
        for line in msg.read_text().splitlines():
            line = line.split('#')[0].strip()
            if not line or '=' in line:      # comments, constants
                continue
            name = line.split()[1]
            if name != 'header':
                assert re.search(rf'`{name}(\[\])?`', text), f'{msg.stem}.{name}'


def test_the_example_scenario_of_the_design_loads(tmp_path):
    block = re.search(r'```yaml\n(.*?)```', _section(DESIGN.read_text(), 'Scenario contract'),
                      flags=re.S).group(1)
    (tmp_path / 'envs').mkdir()
    shutil.copy(ROOT / 'scenarios' / 'envs' / 'rand_discoverable.txt', tmp_path / 'envs')
    (tmp_path / 'example.yaml').write_text(block)
    scenario = load_scenario(tmp_path / 'example.yaml')
    assert scenario.name == 'rrtqx-paper' and str(scenario.controller.variant) == 'robust'
    assert {'box1', 'late', 'gone'} <= {spec.id for spec in scenario.obstacles}
    assert sum(spec.id.startswith('rand_discoverable_') for spec in scenario.obstacles) == 35
