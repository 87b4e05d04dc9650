"""The volume the twin accepts blocks in: the table top in front of the robot."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene


@dataclass(frozen=True)
class Workspace:
    """Axis-aligned bounds (robot base frame, metres) for every unit cube centre.

    The defaults cover the Panda's reach (about 0.85 m) on the table top; a block
    outside them is refused rather than simulated somewhere nobody can reach.
    """

    lower: tuple[float, float, float] = (-0.3, -0.9, 0.0)
    upper: tuple[float, float, float] = (1.0, 0.9, 1.0)

    def check_points(self, points: np.ndarray, what: str) -> None:
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(points)):
            raise RadError(f'{what}: position is not finite')
        lo, hi = np.asarray(self.lower), np.asarray(self.upper)
        bad = ~np.all((points >= lo) & (points <= hi), axis=1)
        if bad.any():
            p = points[np.argmax(bad)]
            raise RadError(f'{what} at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is outside the workspace '
                           f'{list(self.lower)}..{list(self.upper)} m')

    def check_scene(self, scene: Scene) -> None:
        for block in scene.blocks:
            self.check_points(scene.unit_positions(block), f'block {block.id!r}')
        for t in scene.targets:
            corners = [t.cell_center((0, 0, 0), scene.pitch), t.cell_center(np.asarray(t.size) - 1, scene.pitch)]
            self.check_points(np.array(corners), f'target region {t.name!r}')
