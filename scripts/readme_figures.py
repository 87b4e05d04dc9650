"""The README's table of figures, regenerated from the results pages in docs/results.

    python scripts/readme_figures.py           # rewrite the table between the markers in README.md
    python scripts/readme_figures.py --check   # exit 1, naming each figure, where README and pages differ

Each figure is a cell (or cells) of one results page's table (`FIGURES`): the line whose columns
hold the given values, the named columns joined by " / ". The table sits between
`<!-- figures:start -->` and `<!-- figures:end -->` in README.md; tests/test_readme_figures.py runs
the check.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / 'docs' / 'results'
README = ROOT / 'README.md'
START, END = '<!-- figures:start -->', '<!-- figures:end -->'

# (figure, page, the line: {column: value}, the columns shown, scenes)
FIGURES = [
    ('`default`, robot in the loop, g = 5 flush: coverage / f', 'eval', {'grid': '5'}, ('coverage', 'f'),
     '40 unseen'),
    ('`default`, g = 6 flush: coverage / f', 'eval', {'grid': '6'}, ('coverage', 'f'), '20 unseen'),
    ('`default`, held-out shapes: coverage / f', 'ceiling', {'scene set': 'shapes-holdout', 'agent': '`*'},
     ('coverage', 'f'), '9'),
    ('`default`, their tight layouts (blocks 2.5 cm apart): coverage / f', 'ceiling',
     {'scene set': 'shapes-tight', 'agent': '`*'}, ('coverage', 'f'), '9'),
    ('`default` below the robot-feasible ceiling, g = 5 (mean where known)', 'ceiling',
     {'scene set': 'g5-c0-n30', 'agent': '`*'}, ('below the known ceiling',), '30'),
    ('`default`, hard shapes: coverage / f', 'hard', {'agent': 'default'}, ('a-bar', 'f'), '11'),
    ('`default`, held-out shapes executed with the arm, realistic faults: coverage', 'execution',
     {'scene set': 'held-out shapes', 'run': 'simulate/realistic'}, ('coverage',), '9'),
    ('`/plan_assembly` over DDS, g = 5, no time limit asked: median / p95 / max (s) / mean predicted coverage',
     'plan_assembly', {'time_limit_s': '0 (anytime, 2.25)'},
     ('median (s)', 'p95 (s)', 'max (s)', 'mean predicted coverage'), '20 unseen'),
    ('`/plan_assembly` with `time_limit_s` 2: max (s) / mean predicted coverage', 'plan_assembly',
     {'time_limit_s': '2'}, ('max (s)', 'mean predicted coverage'), '20 unseen'),
    ('Table II, g = 5, clearance 0.2: `paper` (rad\'s MILP-DQN-MCTS): coverage / f', 'table2', {'agent': 'paper'},
     ('g = 5, clearance 0.2: a-bar / f',), '30'),
    ('Table II, g = 5, clearance 0.2: the paper\'s own MILP-DQN-MCTS', 'table2', {'agent': 'paper (paper)'},
     ('g = 5, clearance 0.2: a-bar / f',), ''),
    ('Table II, g = 4, clearance 0.2: `paper`: coverage / f', 'table2', {'agent': 'paper'},
     ('g = 4, clearance 0.2: a-bar / f',), '30'),
    ('Table II, g = 4, clearance 0.2: the paper\'s own MILP-DQN-MCTS', 'table2', {'agent': 'paper (paper)'},
     ('g = 4, clearance 0.2: a-bar / f',), ''),
    ('Table II, g = 5, clearance 0.2: `default` of that run (look-ahead, stable allocation)', 'table2',
     {'agent': 'default'}, ('g = 5, clearance 0.2: a-bar / f',), '30'),
    ('Table II, g = 5, clearance 0.2: `heur` (the paper\'s HEUR): coverage / f', 'table2', {'agent': 'heur'},
     ('g = 5, clearance 0.2: a-bar / f',), '30'),
    ('Table II, g = 5, clearance 0.2: the paper\'s own HEUR', 'table2', {'agent': 'heur (paper)'},
     ('g = 5, clearance 0.2: a-bar / f',), ''),
    ('Table II, g = 5, clearance 0.2: `heur-verified`: coverage / f', 'table2', {'agent': 'heur-verified'},
     ('g = 5, clearance 0.2: a-bar / f',), '30'),
    ('Without the robot, g = 5: the mixed network, stable allocation (Table I; the paper 0.85)', 'table1',
     {'allocation': 'stable', 'agent': '**MILP-DQN-mixed**'}, ('g = 5',), '200 unseen'),
    ('`default`, Duplo-style tasks of 2-12 studded bricks, the hand pressing each home: coverage / whole / f',
     'bricks', {'effector': 'hand', 'set': 'duplo tasks'}, ('coverage', 'whole', 'f'), '22'),
]


def page_table(name: str, root: Path = ROOT) -> list[dict[str, str]]:
    """The first table of docs/results/<name>.md, a dict per line keyed by the header."""
    lines = [line.strip() for line in (root / 'docs' / 'results' / f'{name}.md').read_text().splitlines()]
    start = next(i for i, line in enumerate(lines) if line.startswith('|'))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith('|')), len(lines))
    cells = [[c.strip() for c in line.strip('|').split('|')] for line in lines[start:end]]
    return [dict(zip(cells[0], row)) for row in cells[2:]]


def matches(cell: str, wanted: str) -> bool:
    """A cell matches its value exactly, or by prefix where the value ends in '*'."""
    return cell.startswith(wanted[:-1]) if wanted.endswith('*') else cell == wanted


def figure(page: list[dict[str, str]], where: dict[str, str], columns, label: str) -> str:
    found = [row for row in page if all(matches(row.get(k, ''), v) for k, v in where.items())]
    if len(found) != 1:
        raise SystemExit(f'{label}: {len(found)} lines of its page match {where} (one expected)')
    return ' / '.join(found[0][c] for c in columns)


def rows(root: Path = ROOT) -> list[tuple[str, str, str, str]]:
    """(figure, value, scenes, page link) for every figure, read from the pages now."""
    pages: dict[str, list[dict[str, str]]] = {}
    out = []
    for label, name, where, columns, scenes in FIGURES:
        page = pages.setdefault(name, page_table(name, root))
        out.append((label, figure(page, where, columns, label), scenes,
                    f'[{name}](docs/results/{name}.md)'))
    return out


def table(root: Path = ROOT) -> str:
    lines = ['| figure | value | scenes | page |', '|---|---|---|---|']
    lines += [f'| {label} | {value} | {scenes} | {link} |' for label, value, scenes, link in rows(root)]
    return '\n'.join(lines)


def block(text: str) -> tuple[int, int]:
    """The span of the text between the markers."""
    if START not in text or END not in text:
        raise SystemExit(f'README.md has no {START} ... {END} block')
    return text.index(START) + len(START), text.index(END)


def differences(readme_text: str, root: Path = ROOT) -> list[str]:
    """One line per figure whose README line differs from what the pages say (and per README line that
    is not a figure of the pages)."""
    a, b = block(readme_text)
    have = {}
    for line in readme_text[a:b].strip().splitlines()[2:]:
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        have[cells[0]] = line.strip()
    out = []
    for label, value, scenes, link in rows(root):
        line = have.pop(label, None)
        if line != f'| {label} | {value} | {scenes} | {link} |':
            said = line.split('|')[2].strip() if line else 'nothing'
            page = link[link.index('(') + 1:-1]
            out.append(f'{label}: README says {said}, {page} says {value}')
    out += [f'README line not made from the results pages: {line}' for line in have.values()]
    return out


def rewrite(readme_text: str, root: Path = ROOT) -> str:
    a, b = block(readme_text)
    return readme_text[:a] + '\n' + table(root) + '\n' + readme_text[b:]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--check', action='store_true', help='do not write; exit 1 if README and the pages differ')
    args = p.parse_args(argv)
    text = README.read_text()
    if args.check:
        problems = differences(text)
        for line in problems:
            print(line, file=sys.stderr)
        if problems:
            print('README.md and docs/results disagree: run python scripts/readme_figures.py', file=sys.stderr)
        return 1 if problems else 0
    new = rewrite(text)
    if new != text:
        README.write_text(new)
        print('README.md: figures rewritten')
    return 0


if __name__ == '__main__':
    sys.exit(main())
