"""Where evaluation scenes come from: the generator, or a folder of scene files."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene


def generated_scenes(grid: int, sides: int, n: int, seed: int) -> Iterator[tuple[str, Scene]]:
    """n generator scenes with seeds seed .. seed + n - 1, made as they are needed."""
    config = GeneratorConfig(grid=grid, sides=sides)
    config.validate()
    for s in range(seed, seed + n):
        yield f'g{grid}-sides{sides}-seed{s}', generate_scene(config, s)


def scene_dir(path: str | Path) -> list[tuple[str, Scene]]:
    """Every *.json in a folder, sorted by name, all read before any episode runs,
    so a bad file stops the run at once with its name."""
    folder = Path(path)
    if not folder.is_dir():
        raise RadError(f'scene folder {str(folder)!r} does not exist or is not a folder')
    files = sorted(folder.glob('*.json'))
    if not files:
        raise RadError(f'scene folder {str(folder)!r} holds no *.json files')
    scenes = []
    for f in files:
        try:
            scenes.append((f.stem, Scene.load(f)))
        except RadError as e:
            raise RadError(f'bad scene file {str(f)!r}: {e}') from None
    return scenes


