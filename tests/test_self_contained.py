"""The repository is self-contained: no tracked file reads or links a place outside it.

A clone on a fresh machine, with nothing beside it, must build, test and explain itself
(docs/design.md, docs/papers.md, the vendored test data). The project grew up next to
a sibling directory of shared documents; this check fails, naming each file and line,
when anything points there again: the relative sibling path (one or more parent steps,
then ``shared``), its absolute path on the build machine, a path to it assembled in code
from ``parent`` and ``'shared'``, or the bare names of the documents that lived there
(their content is in docs/design.md now).

The patterns are assembled from pieces so that this file does not match itself.
"""

from __future__ import annotations

import os
import pathlib
import re
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[1]

_SHARED = 'sha' + 'red'
_ELSEWHERE = ('DES' + 'IGN', 'ST' + 'YLE', 'ROS2_ON' + '_PYPI')   # documents that lived there
PATTERNS = (
    (re.compile(r'(?:\.\./)+' + _SHARED + r'\b'), 'the sibling directory beside the clone'),
    (re.compile(re.escape('/work/' + _SHARED)), "the sibling directory's absolute path"),
    (re.compile(r'\bparents?\b.*/\s*[\'"]' + _SHARED + r'[\'"]'),
     'a path to the sibling directory built in code'),
    (re.compile(r'\b(?:' + '|'.join(_ELSEWHERE) + r')\.md\b'),
     'a document that is not in the repository'),
)
# Not part of the repository: environments, build products, run outputs.
UNTRACKED_DIRS = frozenset({'.git', '.venv', 'build', 'install', 'log', 'runs', '.stamps',
                            '__pycache__', '.pytest_cache', 'node_modules'})


def repository_files(root: pathlib.Path) -> list[pathlib.Path]:
    """The files of the repository at ``root``, sorted.

    In a git checkout: what git tracks (``git ls-files``), as far as it exists on disk.
    Without ``.git`` (an exported tree): every file, except under the directories that
    hold environments, build products and run outputs.
    """
    if (root / '.git').exists():   # a directory, or a file in a git worktree
        listing = subprocess.run(['git', 'ls-files', '-z'], cwd=root, check=True,
                                 capture_output=True).stdout.decode()
        return sorted(p for p in (root / name for name in listing.split('\0') if name)
                      if p.is_file())
    found = []
    for here, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in UNTRACKED_DIRS and not d.endswith('.egg-info')]
        found += [pathlib.Path(here) / f for f in files]
    return sorted(found)


def outside_references(root: pathlib.Path) -> list[str]:
    """``path:line: what it points at: the line`` for every reference outside the repository."""
    hits = []
    for path in repository_files(root):
        data = path.read_bytes()
        if b'\0' in data:
            continue   # binary
        text = data.decode('utf-8', errors='replace')
        for number, line in enumerate(text.splitlines(), start=1):
            for pattern, what in PATTERNS:
                if pattern.search(line):
                    hits.append(f'{path.relative_to(root)}:{number}: {what}: {line.strip()}')
                    break
    return hits


def test_no_file_of_the_repository_points_outside_it():
    hits = outside_references(ROOT)
    assert not hits, ('files reference places outside the repository (a fresh clone has '
                      'nothing beside it):\n' + '\n'.join(hits))


def _plant(root: pathlib.Path) -> dict[str, str]:
    """Files with and without outside references; returns name -> text."""
    sibling = '../' + _SHARED
    files = {
        'README.md': f'See [the design]({sibling}/{_ELSEWHERE[0]}.md), docs/design.md.\nfine\n',
        'docs/a.md': f'fine\nfrom scenarios/: ../{sibling}/peer-envs/X.txt\n',
        'tests/t.py': f"peer = ROOT.parent / '{_SHARED}' / 'x'\nok = ROOT / 'shared_data'\n",
        'ci.sh': f'cp /work/{_SHARED}/papers/x.txt .\n',
        'notes.txt': f'read {_ELSEWHERE[1]}.md first; docs/design.md is ours\n',
        'clean.py': "print('shared memory, sharedctypes, docs/design.md')\n",
        '.venv/lib/x.py': f'# {sibling}\n',
        'runs/r/summary.json': f'"{sibling}"\n',
        'blob.bin': f'\0{sibling}',
    }
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return files


EXPECTED = {'README.md:1', 'docs/a.md:2', 'tests/t.py:1', 'ci.sh:1', 'notes.txt:1'}


def test_the_check_finds_each_reference_in_a_tree_without_git(tmp_path):
    _plant(tmp_path)
    hits = outside_references(tmp_path)
    # environments and run outputs are not the repository; binaries are not read
    assert {':'.join(h.split(':')[:2]) for h in hits} == EXPECTED
    assert len(hits) == len(EXPECTED)


def test_the_check_reads_what_git_tracks(tmp_path):
    _plant(tmp_path)
    subprocess.run(['git', 'init', '-q'], cwd=tmp_path, check=True)
    subprocess.run(['git', 'add', 'README.md', 'clean.py', 'tests/t.py'], cwd=tmp_path,
                   check=True)
    hits = [':'.join(h.split(':')[:2]) for h in outside_references(tmp_path)]
    assert hits == ['README.md:1', 'tests/t.py:1']      # untracked files are not looked at
