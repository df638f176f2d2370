"""The README's and docs/'s links lead somewhere: every relative link or image names a
file of the repository, and every anchor (``#...``, in the same document or another) a
heading of the document it points into, as GitHub slugs headings."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]
#: a Markdown link's or image's target: ](target)
LINK = re.compile(r'\[[^\]]*\]\(([^)\s]+)\)')
HEADING = re.compile(r'^#{1,6} +(.+?) *#*$')
CODE_FENCE = re.compile(r'^\s*```')


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, inline code marks and punctuation other
    than '-' and '_' dropped, spaces made '-'."""
    text = heading.strip().lower().replace('`', '')
    text = re.sub(r'[^\w\- ]', '', text)
    return text.replace(' ', '-')


def anchors(path: Path) -> set[str]:
    """The anchors of the headings of the Markdown file ``path`` (a repeated heading's
    second anchor gets '-1', and so on), code blocks left out."""
    seen: dict[str, int] = {}
    found = set()
    in_code = False
    for line in path.read_text().splitlines():
        if CODE_FENCE.match(line):
            in_code = not in_code
            continue
        match = None if in_code else HEADING.match(line)
        if match:
            base = slug(match.group(1))
            count = seen.get(base, 0)
            seen[base] = count + 1
            found.add(base if count == 0 else f'{base}-{count}')
    return found


def links(path: Path) -> list[str]:
    """The relative link targets of ``path``, outside code blocks."""
    targets = []
    in_code = False
    for line in path.read_text().splitlines():
        if CODE_FENCE.match(line):
            in_code = not in_code
        elif not in_code:
            targets += [t for t in LINK.findall(line) if not re.match(r'[a-z]+:', t)]
    return targets


def test_slug_follows_githubs_rule():
    assert slug('The 2D barrier model and the Fin Ray finger') == \
        'the-2d-barrier-model-and-the-fin-ray-finger'
    assert slug('Topics (names relative to the node `/gripper_sim`)') == \
        'topics-names-relative-to-the-node-gripper_sim'
    assert slug('Walk-through: a peach') == 'walk-through-a-peach'


def test_repeated_headings_are_numbered(tmp_path):
    page = tmp_path / 'page.md'
    page.write_text('# Speed\n\n```\n# not a heading\n```\n\n## Speed\n')
    assert anchors(page) == {'speed', 'speed-1'}


@pytest.mark.parametrize('document', DOCUMENTS, ids=lambda p: p.name)
def test_every_relative_link_and_anchor_resolves(document):
    broken = []
    for target in links(document):
        file_part, _, anchor = target.partition('#')
        linked = (document.parent / file_part).resolve() if file_part else document
        if not linked.exists():
            broken.append(f'{target}: no file {linked.relative_to(ROOT)}')
        elif anchor and linked.suffix == '.md' and anchor not in anchors(linked):
            broken.append(f'{target}: no heading with that anchor in {linked.name}')
    assert not broken, f'{document.name}: ' + '; '.join(broken)
