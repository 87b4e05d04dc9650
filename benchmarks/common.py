"""What more than one benchmark uses: the generated scenes of Table II, the hand-made shape sets,
the number format of the tables, and where results go.

Every benchmark writes two committed files under docs/results/: `<name>.md`, the table with the
command that made it, and `<name>.rows.jsonl`, one compact JSON line per measured row (per scene
and agent), so a figure can be traced to its scenes. Caches that let an interrupted run resume
live under out/cache/<name>/ (not committed: the benchmark regenerates them).

Benchmarks import it as `from common import ...` (each script runs from benchmarks/).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / 'docs' / 'results'
CACHE = ROOT / 'out' / 'cache'


def scenes(grid: int, n: int, clearance: float):
    from rad_core.generator import GeneratorConfig, generate_scene
    kw = {'clearance': clearance} if clearance else {}
    config = GeneratorConfig(grid=grid, sides=2, **kw)
    for s in range(n):
        yield f'g{grid}-c{clearance:g}-seed{s}', generate_scene(config, s)


def shape_scenes(split: str):
    """Hand-made shapes (rad_core.shapes): 'train', 'holdout', or 'tight' (the held-out shapes
    with their blocks packed at least 2 cm apart on the table instead of 5 cm: only the fingers'
    rubber tips fit between them)."""
    from rad_core import shapes
    if split == 'tight':
        return [(f'{name}-tight', shapes.build_scene(shapes.SPECS[name], 0, config=shapes.LayoutConfig(gap=0.02)))
                for name in shapes.SPLITS['holdout']]
    return [(name, shapes.shape_scene(name)) for name in shapes.SPLITS[split]]


def fmt(v) -> str:
    return '' if v is None else f'{v:.2f}'


def command_line() -> str:
    """How this benchmark was started, as a reader would type it from the repository root."""
    return 'python benchmarks/' + ' '.join([Path(sys.argv[0]).name, *sys.argv[1:]])


def cache_dir(name: str) -> Path:
    """out/cache/<name>/, made if missing: a benchmark's resumable per-run results."""
    path = CACHE / name
    path.mkdir(parents=True, exist_ok=True)
    return path


def compact(value, digits: int = 4):
    """A row made small for the rows file: floats rounded, nested lists and dicts kept."""
    if isinstance(value, float):
        return round(value, digits)
    if isinstance(value, dict):
        return {k: compact(v, digits) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [compact(v, digits) for v in value]
    return value


def write_rows(path: Path, rows, digits: int = 4) -> Path:
    """One compact JSON object per line (`compact`, floats to `digits` decimals), in the order given."""
    path.parent.mkdir(parents=True, exist_ok=True)
    text = ''.join(json.dumps(compact(r, digits), separators=(',', ':'), sort_keys=False) + '\n' for r in rows)
    path.write_text(text)
    return path


def read_rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def cache_path(bench: str, agent: str, set_name: str) -> Path:
    """Where a benchmark keeps one agent's evaluation of one scene set (keyed by the agent's
    canonical text, so a preset and its spelled-out text share it)."""
    from rad_core.agents import label, parse
    return cache_dir(bench) / f'{label(parse(agent))}-{set_name}.json'


def cached_evaluation(bench: str, agent: str, set_name: str, make_scenes, force: bool = False, **kw) -> dict:
    """`evaluation.evaluate` of the agent with the robot (seed 0) on make_scenes(), a list of
    (name, scene), from `cache_path` unless force; the result's 'seconds' is its wall time.
    kw: further arguments of evaluate (allocation, reallocation)."""
    import time

    from rad_core import jsonfmt
    from rad_core.evaluation import evaluate
    from rad_core.progress import ProgressBar
    path = cache_path(bench, agent, set_name)
    if path.exists() and not force:
        return json.loads(path.read_text())
    scenes = list(make_scenes())
    t0 = time.perf_counter()
    result = evaluate(agent, scenes, robot=True, seed=0, progress=ProgressBar(len(scenes), f'{agent} {set_name}'),
                      **kw)
    result['seconds'] = time.perf_counter() - t0
    path.write_text(jsonfmt.dumps(result))
    return result


def agent_legend(agents) -> list[str]:
    """Markdown lines: each agent as given and its canonical text."""
    from rad_core.agents import label, parse
    return ['| agent | canonical text |', '|---|---|'] + [f'| {a} | `{label(parse(a))}` |' for a in agents] + ['']
