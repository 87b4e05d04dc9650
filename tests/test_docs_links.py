"""Every relative link in README.md and docs/*.md leads somewhere: the file exists inside the
repository and, for a link with a #fragment into a Markdown page, that page has the heading.

Links are Markdown's inline form, [text](target) and ![alt](target); text inside code
(fenced blocks and `spans`) is not a link. Fragments are matched against headings
slugged the way GitHub renders them.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from ros_harness import REPO_ROOT

LINK = re.compile(r'!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+"[^"]*")?\s*\)')
FENCE = re.compile(r'^\s*(```|~~~)')
CODE_SPAN = re.compile(r'`+[^`]*`+')
HEADING = re.compile(r'^\s{0,3}#{1,6}\s+(.*?)\s*#*\s*$')
EXTERNAL = re.compile(r'^[a-zA-Z][a-zA-Z0-9+.-]*:')   # http:, https:, mailto:, ...


def prose_lines(text: str) -> list[tuple[int, str]]:
    """(line number, line) of the lines outside fenced code blocks (an unclosed fence hides
    everything after it: test_code_fences_are_closed)."""
    lines, fenced = [], False
    for number, line in enumerate(text.splitlines(), 1):
        if FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            lines.append((number, line))
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r'!?\[([^\]]*)\]\([^)]*\)', r'\1', heading)   # a link's text stays
    text = re.sub(r'[^\w\- ]', '', text.lower())
    return text.replace(' ', '-')


def anchors(page: Path) -> set[str]:
    """The anchors of a Markdown page's headings (a repeated one gets -1, -2, ...)."""
    seen: dict[str, int] = {}
    out = set()
    for _, line in prose_lines(page.read_text(encoding='utf-8')):
        match = HEADING.match(line)
        if not match:
            continue
        base = slug(match.group(1))
        count = seen.get(base, 0)
        seen[base] = count + 1
        out.add(base if count == 0 else f'{base}-{count}')
    return out


def broken_links(page: Path, root: Path) -> list[str]:
    """One line per link of `page` that does not resolve: 'page:line: target: why'."""
    problems = []
    for number, line in prose_lines(page.read_text(encoding='utf-8')):
        for target in LINK.findall(CODE_SPAN.sub('', line)):
            if EXTERNAL.match(target):
                continue
            path_part, _, fragment = target.partition('#')
            dest = (page.parent / path_part).resolve() if path_part else page.resolve()
            where = f'{page.relative_to(root)}:{number}: {target}'
            if not dest.is_relative_to(root.resolve()):
                problems.append(f'{where}: leads outside the repository')
            elif not dest.exists():
                problems.append(f'{where}: no such file')
            elif fragment and dest.suffix == '.md' and fragment not in anchors(dest):
                problems.append(f'{where}: no heading with that anchor in {dest.name}')
    return problems


def pages(root: Path) -> list[Path]:
    return [root / 'README.md', *sorted((root / 'docs').glob('*.md'))]


def test_readme_and_docs_pages_exist():
    assert (REPO_ROOT / 'README.md').is_file()
    assert len(pages(REPO_ROOT)) > 2, 'docs/*.md holds no pages'


@pytest.mark.parametrize('page', pages(REPO_ROOT), ids=lambda p: str(p.relative_to(REPO_ROOT)))
def test_every_relative_link_resolves(page):
    assert broken_links(page, REPO_ROOT) == []


@pytest.mark.parametrize('page', pages(REPO_ROOT), ids=lambda p: str(p.relative_to(REPO_ROOT)))
def test_code_fences_are_closed(page):
    fences = [n for n, line in enumerate(page.read_text(encoding='utf-8').splitlines(), 1) if FENCE.match(line)]
    assert len(fences) % 2 == 0, f'{page.name}: the fence on line {fences[-1]} is never closed'


def test_every_docs_page_is_linked_from_the_readme():
    readme = REPO_ROOT / 'README.md'
    linked = {(readme.parent / t.partition('#')[0]).resolve()
              for _, line in prose_lines(readme.read_text(encoding='utf-8'))
              for t in LINK.findall(CODE_SPAN.sub('', line)) if not EXTERNAL.match(t)}
    missing = [str(p.relative_to(REPO_ROOT)) for p in pages(REPO_ROOT)[1:] if p.resolve() not in linked]
    assert missing == []


def test_the_checker_finds_what_is_broken(tmp_path):
    (tmp_path / 'docs').mkdir()
    (tmp_path / 'docs' / 'a.md').write_text('# Title\n\n## `/plan_assembly` and more\n', encoding='utf-8')
    (tmp_path / 'README.md').write_text(
        '[ok](docs/a.md) [ok anchor](docs/a.md#plan_assembly-and-more) [self](#top-heading)\n'
        '# Top heading\n'
        '[gone](docs/missing.md) [bad anchor](docs/a.md#nowhere) [out](../elsewhere.md)\n'
        '![picture](docs/img/none.png) [web](https://example.org/x.md) `[code](nope.md)`\n'
        '```\n[fenced](nope.md)\n```\n', encoding='utf-8')
    problems = broken_links(tmp_path / 'README.md', tmp_path)
    assert [p.split(': ')[0] + ': ' + p.split(': ')[1] for p in problems] == [
        'README.md:3: docs/missing.md', 'README.md:3: docs/a.md#nowhere', 'README.md:3: ../elsewhere.md',
        'README.md:4: docs/img/none.png']
    assert 'no heading' in problems[1] and 'outside' in problems[2]


def test_slugs_match_githubs():
    assert slug("Trajectory timing and a real Franka's limits") == 'trajectory-timing-and-a-real-frankas-limits'
    assert slug('`/allocate` (allocation_node)') == 'allocate-allocation_node'
    assert slug('Scene files: `rad-scene/1`') == 'scene-files-rad-scene1'
