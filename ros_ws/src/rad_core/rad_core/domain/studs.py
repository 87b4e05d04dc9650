"""Stud systems: bricks that lock onto the studs of the bricks under them (LEGO, Duplo).

A scene without studs (the paper's blocks, rad's default) holds its blocks by gravity and friction
alone, on a lattice of cubes. A scene with a stud system says so in ``studs``: the system's name,
its course height (the lattice's z pitch, which need not be the stud pitch: a LEGO brick is 9.6 mm
tall on an 8 mm pitch) and its clutch, the pull (N) one stud connection holds before it lets go.
The stud pitch is the scene's ``unit``: one stud per lattice column, so a 2 x 4 brick covers 2 x 4
columns. The named systems give their real proportions; a scene scaled to another unit (bricks
printed for a robot) keeps the proportions, and its clutch is the bricks' own (``--clutch``).

Clutch against weight is what decides how far a brick may reach out, so a studded scene also
says what one lattice cell of a brick weighs (``mass``, kg): the system's bricks, hollow as they
are, scaled with the cell's volume where the unit is not the system's own pitch. The physics
world gives the bricks that mass and the statics count in that weight.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StudSystem:
    """A family of studded bricks at its real size (m, N)."""

    name: str
    pitch: float
    """Stud to stud (m)."""
    brick: float
    """A brick's height without its studs (m)."""
    plate: float | None
    """A plate's height (m), None where the system has none in rad's tables."""
    clutch: float
    """The pull one stud connection holds (N), a nominal value for new bricks."""
    brick_mass: float
    """The mass (kg) of a brick per stud (a 2 x 4's over 8), at the system's own size."""
    stud: float = 0.0017
    """A stud's height (m): how much higher a brick stands on the studs under it before it is pressed home."""

    def cell_mass(self, unit: float, course: float) -> float:
        """The mass (kg) of one lattice cell `unit` square and `course` high, of this system's bricks."""
        return self.brick_mass * (unit / self.pitch) ** 2 * (course / self.brick)

    def course_ratio(self, plates: bool = False) -> float:
        """The lattice's z pitch over its stud pitch: a brick's height, or a plate's."""
        return (self.plate if plates and self.plate else self.brick) / self.pitch


SYSTEMS: dict[str, StudSystem] = {
    'lego': StudSystem('lego', 0.008, 0.0096, 0.0032, 1.0, 0.00232 / 8, 0.0017),
    'duplo': StudSystem('duplo', 0.016, 0.0192, None, 2.0, 0.014 / 8, 0.0045),
}
"""The systems rad knows by name. Clutch (the force model: `rad_core.domain.statics`): published LEGO
figures run from 0.7 N a friction point (BrickSim) and 0.98 N a point, three or four points a stud
(StableLego, Liu et al. 2024), to about 3 N a stud (Funes and Pollack's 12.7 N mm a joint); 1 N is
the cautious value for worn bricks. For Duplo no measurement was found: 2 N is an estimate. A scene
gives its own bricks' value (``studs.clutch``, ``--clutch``). Masses: a LEGO 2 x 4 brick (3001) weighs
2.32 g; a Duplo 2 x 4 about 14 g (an estimate: its walls are not twice LEGO's). Stud heights: LEGO's
1.7 mm; Duplo's 4.5 mm is an estimate. A system rad does not know has LEGO's proportions."""


def stud_height(system: str, unit: float) -> float:
    """How high (m) a stud of `system` stands at a stud pitch of `unit` (m): the system's own proportion,
    LEGO's for a system rad does not know."""
    known = SYSTEMS.get(system, SYSTEMS['lego'])
    return known.stud / known.pitch * unit

GRAVITY = 9.81
"""m/s^2, as the physics world's (`sim.physics.PhysicsConfig.gravity`)."""


@dataclass(frozen=True)
class Studs:
    """A scene's stud system: its name, the lattice's course height (m) and the clutch (N per stud)."""

    system: str
    course: float
    clutch: float
    mass: float
    """kg of one lattice cell of a brick (module docstring)."""
    baseplate: bool = False
    """Whether the table is a baseplate of the system's studs: a brick on the table is pressed onto
    them and held by their clutch, as the bricks above are by the bricks under them. False: the
    bricks of the first course sit loose on the table (gravity and friction)."""

    @property
    def clutch_in_weights(self) -> float:
        """The clutch in weights of one cell: the statics' unit (`domain.statics`)."""
        return self.clutch / (self.mass * GRAVITY)

    def to_dict(self) -> dict:
        doc = {'system': self.system, 'course': self.course, 'clutch': self.clutch, 'mass': self.mass}
        return {**doc, 'baseplate': True} if self.baseplate else doc
