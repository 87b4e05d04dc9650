"""What more than one benchmark uses: the generated scenes of Table II, the hand-made shape sets,
the number format of the tables, the planning-step scene sets, the large voxel designs, and the results
page.

A benchmark that publishes writes one page through `write_page`: docs/results/<name>.md (the
command, the commit, the date, one table and a short note) and docs/results/<name>.rows.jsonl (one
compact JSON line per measured row, so a figure can be traced to its scenes). A new run replaces
both; history lives in git. Caches that let an interrupted run resume live under out/cache/<name>/
(not committed: the benchmark regenerates them).

Benchmarks import it as `from common import ...` (each script runs from benchmarks/); they never
import each other.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / 'docs' / 'results'
CACHE = ROOT / 'out' / 'cache'


def scenes(grid: int, n: int, clearance: float):
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    kw = {'clearance': clearance} if clearance else {}
    config = GeneratorConfig(grid=grid, sides=2, **kw)
    for s in range(n):
        yield f'g{grid}-c{clearance:g}-seed{s}', generate_scene(config, s)


def shape_scenes(split: str):
    """Hand-made shapes (rad_core.domain.shapes): 'train', 'holdout', or 'tight' (the held-out shapes
    with their blocks packed at least 2 cm apart on the table instead of 5 cm: only the fingers'
    rubber tips fit between them)."""
    from rad_core.domain import shapes
    if split == 'tight':
        return [(f'{name}-tight', shapes.build_scene(shapes.SPECS[name], 0, config=shapes.LayoutConfig(gap=0.02)))
                for name in shapes.SPLITS['holdout']]
    return [(name, shapes.shape_scene(name)) for name in shapes.SPLITS[split]]


def fmt(v, spec: str = '.2f') -> str:
    return '' if v is None else format(v, spec)


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
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def page_meta(path: Path) -> dict:
    """The command, commit and date a results page states ({} for a page without them): what a page
    rebuilt from its rows keeps."""
    meta = {}
    if Path(path).exists():
        for line in Path(path).read_text().splitlines():
            for key in ('command', 'commit', 'date'):
                if line.startswith(f'- {key}: '):
                    meta[key] = line[len(f'- {key}: '):].strip().strip('`')
    return meta


def cache_path(bench: str, agent: str, set_name: str) -> Path:
    """Where a benchmark keeps one agent's evaluation of one scene set (keyed by the agent's
    canonical text, so a preset and its spelled-out text share it)."""
    from rad_core.sequencing.decide.agents import label, parse
    return cache_dir(bench) / f'{label(parse(agent))}-{set_name}.json'


def cached_evaluation(bench: str, agent: str, set_name: str, make_scenes, force: bool = False, **kw) -> dict:
    """`evaluation.evaluate` of the agent with the robot (seed 0) on make_scenes(), a list of
    (name, scene), from `cache_path` unless force; the result's 'seconds' is its wall time.
    kw: further arguments of evaluate (allocation, reallocation)."""
    import time

    from rad_core.domain import jsonfmt
    from rad_core.experiment.evaluation import evaluate
    from rad_core.view.progress import ProgressBar
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
    from rad_core.sequencing.decide.agents import label, parse
    return ['| agent | canonical text |', '|---|---|'] + [f'| {a} | `{label(parse(a))}` |' for a in agents] + ['']


def git_commit() -> str:
    """The short hash of HEAD, with '+dirty' when tracked files differ from it ('unknown' outside git)."""
    def git(*args):
        return subprocess.run(['git', *args], cwd=ROOT, capture_output=True, text=True, check=False)
    head = git('rev-parse', '--short', 'HEAD')
    if head.returncode != 0:
        return 'unknown'
    dirty = git('status', '--porcelain', '--untracked-files=no', '--', 'ros_ws', 'benchmarks').stdout.strip()
    return head.stdout.strip() + ('+dirty' if dirty else '')


def cell(value) -> str:
    """A table cell: None empty, floats as given by the caller (format them first), '|' escaped."""
    return '' if value is None else str(value).replace('|', '\\|')


def split_table(lines: list[str]) -> tuple[list[str], list[list[str]]]:
    """A Markdown table's lines (header, rule, rows) as headers and rows of cells, for `write_page`."""
    def cells(line):
        return [c.strip() for c in line.strip().strip('|').split('|')]
    body = [line for line in lines if line.strip().startswith('|')]
    return cells(body[0]), [cells(line) for line in body[2:]]


def page_text(title: str, command: str, commit: str, date: str, headers, table_rows, note: str,
              rows_name: str | None) -> str:
    """The results page: a title, the command, commit and date, one table, a short note."""
    lines = [f'# {title}', '', f'- command: `{command}`', f'- commit: {commit}', f'- date: {date}']
    if rows_name:
        lines.append(f'- rows: [{rows_name}]({rows_name})')
    lines += ['', '| ' + ' | '.join(headers) + ' |', '|' + '---|' * len(headers)]
    lines += ['| ' + ' | '.join(cell(v) for v in row) + ' |' for row in table_rows]
    lines += ['', note.strip(), '']
    return '\n'.join(lines)


def write_page(name: str, title: str, headers, table_rows, note: str, rows=None, *, command: str | None = None,
               commit: str | None = None, date: str | None = None, results: Path | str = RESULTS,
               digits: int = 4) -> Path:
    """Write <results>/<name>.md, the benchmark's one page, and <results>/<name>.rows.jsonl (`write_rows`)
    when rows are given (without them, an existing rows file stays and is linked). The page states
    `command` (default: this process's `command_line()`), the commit (default `git_commit()`) and the
    UTC date (default today), then one table (headers, then table_rows, lists of cells already
    formatted) and the note, a few lines on what the table shows.
    A page rebuilt from a rows file passes the command, commit and date of the run that measured them.
    Returns the page."""
    out = Path(results)
    out.mkdir(parents=True, exist_ok=True)
    rows_file = out / f'{name}.rows.jsonl'
    if rows is not None:
        write_rows(rows_file, rows, digits)
    rows_name = rows_file.name if rows_file.exists() else None   # rows=None: a rows file already there stays
    text = page_text(title, command or command_line(), commit or git_commit(),
                     date or time.strftime('%Y-%m-%d', time.gmtime()), headers, table_rows, note, rows_name)
    page = out / f'{name}.md'
    page.write_text(text)
    return page


# The planning-twin step's scenes, shared by bench_planning_step.py and bench_at_rest.py.

# Generator settings of a harder table: blocks packed 5 mm apart out to the edge of reach, the
# structure farther out, where grasps and reach fail.
HARD_TABLE = dict(gap=0.005, reach=0.86, table_x=(0.3, 0.86), structure_x=0.6)
# The wider set's generated kinds: (label, generator settings).
WIDE_GENERATED = [('g4', dict(grid=4)), ('g5', dict(grid=5)), ('g6', dict(grid=6)),
                  ('g5-tight', dict(grid=5, **HARD_TABLE)), ('g5-u4', dict(grid=5, unit=0.04, gap=0.01)),
                  ('g4-far', dict(grid=4, structure_x=0.84, reach=0.9, table_x=(0.3, 0.9)))]


def wide_scenes(n_seeds: int) -> list[tuple[str, object]]:
    """The settling benchmark's wider set: six kinds of generated scene, n_seeds seeds each from 6000,
    and every hand-made shape (layout seed 0)."""
    from rad_core.domain.generator import GeneratorConfig, generate_scene
    from rad_core.domain.shapes import SPECS, build_scene
    out = []
    for label, kw in WIDE_GENERATED:
        for s in range(6000, 6000 + n_seeds):
            out.append((f'{label}-seed{s}', generate_scene(GeneratorConfig(**kw), s)))
    for name in sorted(SPECS):
        out.append((f'shape-{name}', build_scene(SPECS[name], 0)))
    return out


def candidates(env, guide, rng, k: int) -> list:
    """Up to k allocation actions: a seeded draw among the fully supported ones, then one that is not."""
    from rad_core.sequencing import supported_actions
    allowed = guide.allowed_actions(env.state)
    supported = supported_actions(env, allowed)
    unsupported = [a for a in allowed if a not in set(supported)]
    picked = [supported[i] for i in rng.permutation(len(supported))[:max(0, k - 1)]]
    if unsupported:
        picked.append(unsupported[int(rng.integers(len(unsupported)))])
    return picked


# ---- large voxel designs (bench_designs, bench_large --designs) ------------------------------------

def _box(g, lo, hi):
    g[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True


def _corners(g, xs, ys, size, height):
    """Four posts (legs, wheels) of `size` (x, y) cells, from the ground to `height`, at each x in xs and y in ys."""
    for x in xs:
        for y in ys:
            _box(g, (x, y, 0), (x + size[0], y + size[1], height))


def designs() -> dict[str, np.ndarray]:
    """name -> occupancy [x, y, z], z up."""
    out = {}
    g = np.zeros((16, 12, 9), dtype=bool)                       # table: a top on four legs
    _box(g, (0, 0, 8), (16, 12, 9))
    _corners(g, (0, 14), (0, 10), (2, 2), 8)
    out['table'] = g
    g = np.zeros((12, 12, 16), dtype=bool)                      # chair: seat, back, legs
    _box(g, (0, 0, 6), (12, 12, 8))
    _box(g, (0, 10, 8), (12, 12, 16))
    _corners(g, (0, 10), (0, 10), (2, 2), 6)
    out['chair'] = g
    g = np.zeros((18, 10, 9), dtype=bool)                       # sofa: base, back, arms
    _box(g, (0, 0, 0), (18, 8, 4))
    _box(g, (0, 8, 0), (18, 10, 9))
    _box(g, (0, 0, 4), (2, 8, 7))
    _box(g, (16, 0, 4), (18, 8, 7))
    out['sofa'] = g
    g = np.zeros((18, 10, 8), dtype=bool)                       # car: wheels, body, cabin
    _corners(g, (2, 13), (0, 8), (3, 2), 2)
    _box(g, (0, 0, 2), (18, 10, 5))
    _box(g, (5, 1, 5), (14, 9, 8))
    out['car'] = g
    g = np.zeros((20, 8, 10), dtype=bool)                       # train: engine with a chimney, two wagons
    for x0, x1 in ((0, 7), (8, 13), (14, 20)):
        _box(g, (x0, 0, 0), (x1, 8, 5))
    _box(g, (0, 1, 5), (4, 7, 8))
    _box(g, (5, 3, 5), (7, 5, 10))
    out['train'] = g
    out['solid 20 x 15 x 7'] = np.ones((20, 15, 7), dtype=bool)
    return out


THIN_LETTERS = {
    # Rows top first; '#' is a stroke two cells wide and three courses high, two cells deep.
    'H': ['#.#', '#.#', '###', '#.#', '#.#'],
    'T': ['###', '.#.', '.#.', '.#.', '.#.'],
    'E': ['###', '#..', '##.', '#..', '###'],
    'A': ['.#.', '#.#', '###', '#.#', '#.#'],
}


def thin_designs() -> dict[str, np.ndarray]:
    """name -> occupancy [x, y, z], z up: thin, tall designs two cells deep (letters, stairs, towers, a
    wall with a door), as people draw them for a 2 cm unit. Some overhang (T's bar, A's apex, E's arms,
    the door's lintel), so part of them cannot stand on blocks that only rest."""
    out = {}
    for ch, rows in THIN_LETTERS.items():
        g = np.zeros((6, 2, 15), dtype=bool)
        for r, row in enumerate(rows):
            z0 = 3 * (len(rows) - 1 - r)
            for c, v in enumerate(row):
                if v == '#':
                    _box(g, (2 * c, 0, z0), (2 * c + 2, 2, z0 + 3))
        out[f'letter {ch}'] = g
    g = np.zeros((14, 2, 14), dtype=bool)                       # stairs: one cell a step
    for x in range(14):
        _box(g, (x, 0, 0), (x + 1, 2, x + 1))
    out['stairs'] = g
    out['tower'] = np.ones((2, 2, 16), dtype=bool)
    g = np.ones((3, 2, 16), dtype=bool)                         # a tower that steps in halfway up
    g[2, :, 8:] = False
    out['stepped tower'] = g
    g = np.ones((12, 2, 10), dtype=bool)                        # a wall with a door
    g[4:8, :, :6] = False
    out['door wall'] = g
    return out


def design_scene(name: str, grid: np.ndarray, unit: float, time_limit: float):
    """One design through `rad scene from-voxels`'s code (`voxel_models`, `placement`, `place_regions`,
    `supply` with the default block set, the hand's order asked, --supply auto): (scene, supply report,
    the fit chosen as text). Raises RadError where the design cannot become a scene."""
    from rad_core.allocation.supply import SupplyParams, supply
    from rad_core.domain.blocks import DEFAULT_LIBRARY
    from rad_core.domain.voxels import place_regions, placement, voxel_models
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f'{name.split()[0]}.npy'
        np.save(path, grid)
        models = voxel_models([(name.split()[0], str(path))], unit)
    chosen = placement(models, unit)
    scene, report = supply(place_regions(models, unit), unit, dict(DEFAULT_LIBRARY),
                           params=SupplyParams(time_limit_s=time_limit))
    return scene, report, f'x {chosen.x:g} m, yaw {chosen.yaw}'
