"""The user docs' relative links lead somewhere: each file exists, each ``#anchor`` is a heading.

The README summarises ``docs/estimators.md`` and ``docs/accuracy.md`` and links into them (and
they back into it), so a heading renamed or a section moved would leave a link that GitHub
renders but that goes nowhere. Anchors follow GitHub's rule: the heading in lower case, without
punctuation other than ``-`` and ``_``, spaces as ``-``, ``-1``, ``-2``... on repeats.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / 'README.md', REPO / 'benchmarks' / 'README.md', *sorted(REPO.glob('docs/*.md'))]

_FENCE = re.compile(r'^```.*?^```', re.MULTILINE | re.DOTALL)
_LINK = re.compile(r'\]\(([^)\s]+)\)')
_HEADING = re.compile(r'^#{1,6} (.+)$', re.MULTILINE)


def heading_anchor(heading: str) -> str:
    """GitHub's anchor of a markdown heading's text."""
    text = re.sub(r'[^\w\- ]', '', heading.strip().lower())
    return text.replace(' ', '-')


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a markdown file (outside code fences), repeats numbered."""
    seen: dict[str, int] = {}
    out = set()
    for match in _HEADING.finditer(_FENCE.sub('', path.read_text(encoding='utf-8'))):
        anchor = heading_anchor(match.group(1))
        count = seen.get(anchor, 0)
        seen[anchor] = count + 1
        out.add(anchor if count == 0 else f'{anchor}-{count}')
    return out


def broken_links(path: Path) -> list[str]:
    """The relative links of a markdown file whose file or anchor does not exist."""
    broken = []
    for match in _LINK.finditer(_FENCE.sub('', path.read_text(encoding='utf-8'))):
        target = match.group(1)
        if target.startswith(('http://', 'https://', 'mailto:')):
            continue
        file_part, _, anchor = target.partition('#')
        linked = (path.parent / file_part).resolve() if file_part else path
        if not linked.exists():
            broken.append(f'{target}: no such file')
        elif anchor and linked.suffix == '.md' and anchor not in anchors(linked):
            broken.append(f'{target}: no such heading in {linked.name}')
    return broken


def test_the_docs_exist() -> None:
    assert (REPO / 'docs' / 'estimators.md') in DOCS
    assert (REPO / 'docs' / 'accuracy.md') in DOCS


def test_every_relative_link_of_the_docs_resolves() -> None:
    broken = {str(p.relative_to(REPO)): broken_links(p) for p in DOCS}
    assert {k: v for k, v in broken.items() if v} == {}


def test_the_checker_sees_a_missing_file_heading_and_a_repeated_heading(tmp_path: Path) -> None:
    doc = tmp_path / 'a.md'
    (tmp_path / 'b.md').write_text('# Title\n\n## The `x` (s) part\n', encoding='utf-8')
    doc.write_text(
        '# Top\n\n## Same\n\n## Same\n\n```\n# not a heading\n```\n\n'
        '[ok](b.md#the-x-s-part) [ok](#same-1) [ok](#top) [web](https://example.com/#x)\n'
        '[bad](b.md#the-x-part) [bad](c.md) [bad](#not-a-heading) [bad](#same-2)\n',
        encoding='utf-8',
    )
    assert broken_links(doc) == [
        'b.md#the-x-part: no such heading in b.md',
        'c.md: no such file',
        '#not-a-heading: no such heading in a.md',
        '#same-2: no such heading in a.md',
    ]
