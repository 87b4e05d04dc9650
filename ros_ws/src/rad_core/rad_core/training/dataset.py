"""Training scenes with their allocations, solved once and stored compactly.

The paper trains on a dataset of 50,000 scenes whose MILP solutions are
computed before training, so training never waits for the solver. A dataset
file is gzipped JSON lines (`rad-dataset/1`): a header line, then one line per
scene holding either a generator seed (the scene is regenerated from it, a few
milliseconds) or a whole scene document (hand-made shapes), and the
allocation's placements as [type, target, yaw, [cells]].

Training seeds start at `TRAIN_SEED_BASE` (one million): evaluation uses the
generator seeds from 0, so the training never sees an evaluation scene.
"""

from __future__ import annotations

import gzip
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterable

from rad_core.allocation import AllocationParams, solve
from rad_core.allocation.placements import Placement
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene

FORMAT = 'rad-dataset/1'
TRAIN_SEED_BASE = 1_000_000


@dataclass(frozen=True)
class Entry:
    name: str
    seed: int | None                 # generator seed, or None for a stored scene
    grid: int
    sides: int
    scene_doc: dict | None
    placements: tuple[Placement, ...]

    def scene(self) -> Scene:
        if self.scene_doc is not None:
            return Scene.from_dict(self.scene_doc)
        return generate_scene(GeneratorConfig(grid=self.grid, sides=self.sides), self.seed)


def _placements_doc(placements) -> list:
    return [[p.type, p.target, p.yaw, [list(c) for c in p.cells]] for p in placements]


def _placements(doc) -> tuple[Placement, ...]:
    return tuple(Placement(str(t), str(r), int(y), tuple(tuple(int(v) for v in c) for c in cells))
                 for t, r, y, cells in doc)


def build(path: str | Path, grids: Iterable[int], scenes_per_grid: int, sides: int = 2,
          first_seed: int = TRAIN_SEED_BASE, shapes: Iterable[tuple[str, Scene]] = (),
          params: AllocationParams = AllocationParams(), progress: Callable[[], None] | None = None) -> dict:
    """Generate and allocate scenes_per_grid scenes per grid size (seeds
    first_seed, first_seed + 1, ...), plus any extra (name, scene) shapes; write
    the dataset file. Returns its header."""
    grids = list(grids)
    shapes = list(shapes)
    header = {'format': FORMAT, 'grids': grids, 'sides': sides, 'first_seed': first_seed,
              'scenes_per_grid': scenes_per_grid, 'shapes': [n for n, _ in shapes],
              'allocation': asdict(params), 'created_s': 0.0}
    t0 = time.perf_counter()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + '.tmp')
    lines = []
    for g in grids:
        config = GeneratorConfig(grid=g, sides=sides)
        for seed in range(first_seed, first_seed + scenes_per_grid):
            result = solve(generate_scene(config, seed), params)
            lines.append({'seed': seed, 'grid': g, 'sides': sides, 'placements': _placements_doc(result.placements)})
            if progress:
                progress()
    for name, scene in shapes:
        result = solve(scene, params)
        lines.append({'name': name, 'scene': scene.to_dict(), 'placements': _placements_doc(result.placements)})
        if progress:
            progress()
    header['created_s'] = round(time.perf_counter() - t0, 1)
    header['count'] = len(lines)
    with gzip.open(tmp, 'wt') as f:
        f.write(json.dumps(header) + '\n')
        for line in lines:
            f.write(json.dumps(line, separators=(',', ':')) + '\n')
    tmp.replace(path)
    return header


class Dataset:
    def __init__(self, header: dict, entries: list[Entry], path: str = ''):
        self.header, self.entries, self.path = header, entries, path

    def __len__(self) -> int:
        return len(self.entries)

    @classmethod
    def load(cls, path: str | Path) -> 'Dataset':
        path = Path(path)
        if not path.is_file():
            raise RadError(f'dataset {str(path)!r} does not exist (build it with `rad dataset build`)')
        try:
            with gzip.open(path, 'rt') as f:
                header = json.loads(f.readline())
                if header.get('format') != FORMAT:
                    raise RadError(f'dataset {str(path)!r} has format {header.get("format")!r}, not {FORMAT!r}')
                entries = []
                for n, line in enumerate(f):
                    d = json.loads(line)
                    if 'scene' in d:
                        entries.append(Entry(d['name'], None, 0, 0, d['scene'], _placements(d['placements'])))
                    else:
                        entries.append(Entry(f'g{d["grid"]}-sides{d["sides"]}-seed{d["seed"]}', int(d['seed']),
                                             int(d['grid']), int(d['sides']), None, _placements(d['placements'])))
        except (OSError, EOFError, ValueError, KeyError, TypeError) as e:
            raise RadError(f'dataset {str(path)!r} is corrupt: {type(e).__name__}: {e}') from None
        if not entries:
            raise RadError(f'dataset {str(path)!r} holds no scenes')
        return cls(header, entries, str(path))
