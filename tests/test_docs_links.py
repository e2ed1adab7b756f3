"""Every relative link and image of the documents resolves, anchors included; the README stays short."""

from __future__ import annotations

import pathlib
import re

from rrtq_testing.paths import OTTE

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
DOCUMENTS = [README, *sorted((ROOT / 'docs').rglob('*.md')),
             ROOT / 'scenarios' / 'envs' / 'README.md', OTTE / 'README.md']
README_MAX_LINES = 260

FENCE = re.compile(r'^(```|~~~).*?^\1[ \t]*$', re.M | re.S)
LINK = re.compile(r'(!?)\[((?:[^\[\]]|\[[^\]]*\])*)\]\(([^)\s]+)(?:\s+"[^"]*")?\)')
HEADING = re.compile(r'^(#{1,6})[ \t]+(.+?)[ \t]*#*[ \t]*$', re.M)
OUTSIDE = re.compile(r'[a-z][a-z0-9+.-]*:', re.I)        # http:, https:, mailto:, ...


def prose(text: str) -> str:
    """The text without its fenced code blocks (a ``# comment`` there is not a heading)."""
    return FENCE.sub('', text)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: its text, lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r'!?\[([^\]]*)\]\([^)]*\)', r'\1', heading)      # a link: its text
    text = re.sub(r'[`*]', '', text).strip().lower()
    return re.sub(r'[^\w\- ]', '', text).replace(' ', '-')


def anchors(doc: pathlib.Path) -> set[str]:
    """The anchors of a document's headings, repeated ones numbered as GitHub does."""
    seen: dict[str, int] = {}
    out = set()
    for _, title in HEADING.findall(prose(doc.read_text())):
        base = slug(title)
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f'{base}-{n}')
    return out


def broken_links(doc: pathlib.Path, root: pathlib.Path = ROOT) -> list[str]:
    """Every relative link or image of ``doc`` that does not resolve inside ``root``, and why."""
    problems = []
    for bang, _, target in LINK.findall(prose(doc.read_text())):
        if OUTSIDE.match(target):
            continue
        where, _, anchor = target.partition('#')
        path = (doc.parent / where).resolve() if where else doc
        name = f'{doc.relative_to(root)}: {target}'
        if not path.is_relative_to(root):
            problems.append(f'{name} leaves the repository')
        elif not path.exists():
            problems.append(f'{name} does not exist')
        elif bang and not path.is_file():
            problems.append(f'{name}: an image that is not a file')
        elif anchor and path.suffix == '.md' and anchor not in anchors(path):
            problems.append(f'{name}: no heading with that anchor')
    return problems


def test_every_relative_link_and_image_of_the_documents_resolves():
    problems = [p for doc in DOCUMENTS for p in broken_links(doc)]
    assert not problems, '\n'.join(problems)


def test_the_readme_stays_short():
    lines = README.read_text().count('\n')
    assert lines <= README_MAX_LINES, f'README.md has {lines} lines (at most {README_MAX_LINES})'


def test_the_check_finds_a_broken_link_image_and_anchor(tmp_path):
    (tmp_path / 'b.md').write_text('# Some `code`: title\n\n## Twice\n\n## Twice\n')
    (tmp_path / 'img').mkdir()
    doc = tmp_path / 'a.md'
    doc.write_text('[fine](b.md#some-code-title) [second](b.md#twice-1) ![dir](img)\n'
                   '[gone](c.md) [anchor](b.md#nothing) [up](../x.md) [web](https://x.org)\n'
                   '[self](#here)\n\n## Here\n\n```\n[in code](nowhere.md)\n# not a heading\n```\n')
    found = broken_links(doc, tmp_path)
    assert [p.split(': ', 1)[1] for p in found] == [
        'img: an image that is not a file', 'c.md does not exist',
        'b.md#nothing: no heading with that anchor', '../x.md leaves the repository'], found
