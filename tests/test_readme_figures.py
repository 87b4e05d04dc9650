"""The README's table of figures is what the results pages in docs/results say
(scripts/readme_figures.py regenerates it)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load():
    spec = importlib.util.spec_from_file_location('readme_figures', ROOT / 'scripts' / 'readme_figures.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_figures_agree_with_the_results_pages():
    figures = load()
    problems = figures.differences((ROOT / 'README.md').read_text())
    assert problems == [], 'run python scripts/readme_figures.py:\n' + '\n'.join(problems)


def test_an_altered_figure_is_named():
    figures = load()
    text = (ROOT / 'README.md').read_text()
    label, value, scenes, link = figures.rows()[0]
    line = f'| {label} | {value} | {scenes} | {link} |'
    assert line in text
    altered = text.replace(line, f'| {label} | 0.123 / 9 | {scenes} | {link} |')
    problems = figures.differences(altered)
    assert len(problems) == 1 and label in problems[0] and '0.123 / 9' in problems[0] and value in problems[0]
    assert figures.differences(figures.rewrite(altered)) == []


def test_every_figure_is_one_line_of_its_page():
    figures = load()
    rows = figures.rows()
    assert len(rows) == len(figures.FIGURES)
    assert all(value.strip(' /') for _, value, _, _ in rows)
