"""The colours rad draws things in, one table for every drawing: the snapshot
renderer (`rad_core.view.render`), the Rerun visualizer (`rad_core.view.viz`) and the
twin's PyBullet world (`rad_core.sim.world`). RGB in 0..1.

A leaf module (it needs only the block library), so the simulation can colour
its bodies without depending on the renderer.
"""

from __future__ import annotations

import zlib

from rad_core.domain.blocks import DEFAULT_LIBRARY

PINK = (1.0, 0.42, 0.71)
"""Target cells."""
GREEN = (0.25, 0.75, 0.30)
"""A target region's other cells."""
TABLE = (0.80, 0.76, 0.68)
"""The table."""

# Block colours: the default library's types in a fixed order, others by a hash of the
# name (crc32, the same in every run, unlike hash()). Pink and green are left out.
_PALETTE = (
    (0.90, 0.33, 0.20), (0.20, 0.45, 0.85), (0.95, 0.70, 0.15), (0.55, 0.30, 0.75),
    (0.15, 0.70, 0.75), (0.60, 0.40, 0.25), (0.35, 0.35, 0.40), (0.85, 0.55, 0.45),
    (0.45, 0.60, 0.95), (0.70, 0.65, 0.20), (0.50, 0.15, 0.30), (0.10, 0.30, 0.45),
)
_DEFAULT_ORDER = tuple(DEFAULT_LIBRARY)


def type_colour(name: str) -> tuple[float, float, float]:
    """RGB in 0..1 of a block type, the same in every run and every scene."""
    if name in _DEFAULT_ORDER:
        return _PALETTE[_DEFAULT_ORDER.index(name) % len(_PALETTE)]
    return _PALETTE[zlib.crc32(name.encode()) % len(_PALETTE)]
