"""What more than one benchmark uses: the generated scenes of Table II and the number format of the tables.

Benchmarks import it as `from common import ...` (each script runs from benchmarks/).
"""

from __future__ import annotations


def scenes(grid: int, n: int, clearance: float):
    from rad_core.generator import GeneratorConfig, generate_scene
    kw = {'clearance': clearance} if clearance else {}
    config = GeneratorConfig(grid=grid, sides=2, **kw)
    for s in range(n):
        yield f'g{grid}-c{clearance:g}-seed{s}', generate_scene(config, s)


def fmt(v) -> str:
    return '' if v is None else f'{v:.2f}'
