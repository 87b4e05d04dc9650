"""The assembly MDP of the paper's Sec. III (here without the robot).

State s = (S_U, S_P, T_F, T_E): which blocks are still on the table, which are
placed in which cells, and the target / non-target cells still free. An action
places an unplaced block by one of its primitive units at a free grid cell with
one of four relative rotations (0, 90, 180, 270 degrees about +z), or terminates:
N_U x (N_F + N_E) x 4 + 1 actions, re-indexed every step as cells fill up.

Rewards: 0.2 (dF - dE) per successful placement, -1 and the end of the episode on
an invalid action, +1 when the last target cell is filled. The episode also ends
on the termination action and when no block is left.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace
from typing import NamedTuple, Protocol

import numpy as np

from rad_core.domain import support
from rad_core.domain.coverage import state_coverage
from rad_core.domain.errors import RadError
from rad_core.domain.grid import Grid, blocks_on_grid
from rad_core.domain.scene import Scene
from rad_core.domain.statics import press_load, structure_statics
from rad_core.domain.studs import GRAVITY
from rad_core.sim.physics import PhysicsStability


class Action(NamedTuple):
    """Place scene block `block` so its unit `unit` lands on grid cell `cell`,
    after turning it by rotation * 90 degrees about +z."""

    block: int
    unit: int
    cell: int
    rotation: int

    @property
    def is_terminate(self) -> bool:
        return self.block < 0


TERMINATE = Action(-1, -1, -1, -1)


class Outcome(str, enum.Enum):
    PLACED = 'placed'
    COMPLETED = 'completed'
    TERMINATED = 'terminated'
    NO_BLOCKS = 'no_blocks_left'
    INVALID_BLOCK = 'invalid_block_already_placed'
    INVALID_OFF_GRID = 'invalid_off_grid'
    INVALID_OVERLAP = 'invalid_overlap'
    INVALID_UNSTABLE = 'invalid_unstable'
    # With the robot in the loop (the paper's Table II): no feasible grasp (f_g), a
    # grasp but no feasible placement (f_p), or the motion moved another block.
    INVALID_GRASP = 'invalid_grasp'
    INVALID_PLACEMENT = 'invalid_placement'
    INVALID_DISTURBED = 'invalid_disturbed'

    @property
    def is_invalid(self) -> bool:
        return self.value.startswith('invalid')


@dataclass(frozen=True)
class EnvConfig:
    """MDP constants (the paper's values) and how stability is decided.

    stability: 'physics' (PyBullet decides, after a geometric prune of blocks with
        no support at all), 'support' (geometric only: every unit must rest on the
        table, a placed block, or the block itself; the paper's HEUR rule), or
        'none' (geometry only, for tests of the bookkeeping).
    """

    step_reward: float = 0.2
    invalid_reward: float = -1.0
    completion_bonus: float = 1.0
    gamma: float = 0.999
    stability: str = 'physics'

    def __post_init__(self):
        if self.stability not in ('physics', 'support', 'none'):
            raise RadError(f"stability must be 'physics', 'support' or 'none', got {self.stability!r}")


class StabilityCheck(Protocol):
    """Decides whether a structure stands once a new block is added.

    placed: world unit centres of every block already in the structure;
    new: world unit centres of the block being placed. Returns (stable, reason).
    A scene with a clearance (`rad_core.domain.scene`) passes it as the keyword
    ``clearance`` (a fraction of the unit), one of studded bricks whose courses are not a unit
    high the keyword ``course`` (m); flush scenes of cubes call with three arguments.
    """

    def __call__(self, unit: float, placed: list[np.ndarray], new: np.ndarray) -> tuple[bool, str]: ...


@dataclass
class AssemblyState:
    occupancy: np.ndarray                      # per grid cell: -1 free, else block index
    placed: dict[int, tuple[np.ndarray, int]]  # block index -> (cell ids in unit order, yaw)
    done: bool = False
    steps: int = 0

    def copy(self) -> 'AssemblyState':
        return AssemblyState(self.occupancy.copy(), dict(self.placed), self.done, self.steps)


@dataclass
class StepResult:
    reward: float
    done: bool
    outcome: Outcome
    reason: str = ''
    cells: np.ndarray | None = None
    info: dict = field(default_factory=dict)


def feeder_blocks(scene: Scene, placed) -> tuple[list[int], list[int]]:
    """(block indices in the scene's feeder that can be taken next, those that cannot), given the
    placed blocks: a queue feeder offers the first `window` of its unplaced blocks; a request feeder
    all of them. Blocks on the table are in neither list."""
    feeder = scene.feeder
    if feeder is None:
        return [], []
    index = {b.id: i for i, b in enumerate(scene.blocks)}
    waiting = replace(feeder, blocks=tuple(bid for bid in feeder.blocks if index[bid] not in placed))
    takeable = [index[bid] for bid in waiting.available()]
    return takeable, [index[bid] for bid in waiting.blocks if index[bid] not in takeable]


class AssemblyEnv:
    def __init__(self, scene: Scene, config: EnvConfig = EnvConfig(),
                 stability: StabilityCheck | None = None):
        self.scene = scene
        self.config = config
        self.grid = Grid(scene)
        self.types = [scene.block_types[b.type] for b in scene.blocks]
        self.yaws = [b.yaw for b in scene.blocks]
        # (block type, yaw, unit, cell) -> the cells `resulting_cells` finds (read-only): pure geometry.
        self._cells_of: dict[tuple, np.ndarray | None] = {}
        self.stability = stability if stability is not None else _default_stability(config.stability)
        self._stability_cache: dict = {}
        occupancy = np.full(self.grid.num_cells, -1, dtype=np.int64)
        placed = {}
        for b, cells in blocks_on_grid(scene, self.grid).items():
            occupancy[cells] = b
            placed[b] = (cells, scene.blocks[b].yaw)
        self._initial = AssemblyState(occupancy, placed)
        self.state = self._initial.copy()

    # ---- state views -----------------------------------------------------
    def reset(self) -> AssemblyState:
        self.state = self._initial.copy()
        return self.state

    def clone(self) -> 'AssemblyEnv':
        """A copy sharing scene, grid and caches but with its own state (for search)."""
        other = object.__new__(AssemblyEnv)
        other.__dict__.update(self.__dict__)
        other.state = self.state.copy()
        return other

    def snapshot(self) -> AssemblyState:
        """Everything that decides the next step (a copy: stepping on leaves it intact)."""
        return self.state.copy()

    def restore(self, snapshot: AssemblyState) -> None:
        """Go back to a snapshot of this env (it stays usable for further restores)."""
        self.state = snapshot.copy()

    def unplaced(self) -> list[int]:
        return [b for b in range(len(self.scene.blocks)) if b not in self.state.placed]

    def unplaced_units(self) -> list[tuple[int, int]]:
        """S_U as (block, unit) pairs, in the order the flat action index uses."""
        return [(b, u) for b in self.unplaced() for u in range(self.types[b].size)]

    def free_cells(self) -> np.ndarray:
        return np.flatnonzero(self.state.occupancy < 0)

    def remaining_target_cells(self) -> int:
        return int(np.count_nonzero(self.grid.is_target & (self.state.occupancy < 0)))

    def coverage(self) -> float:
        """Fraction of target cells filled (the paper's a-bar)."""
        return state_coverage(self)

    def num_actions(self) -> int:
        return len(self.unplaced_units()) * len(self.free_cells()) * 4 + 1

    # ---- flat action index (time-varying) --------------------------------
    def encode(self, action: Action) -> int:
        units, free = self.unplaced_units(), self.free_cells()
        if action.is_terminate:
            return len(units) * len(free) * 4
        try:
            u = units.index((action.block, action.unit))
        except ValueError:
            raise RadError(f'block {action.block} unit {action.unit} is not an unplaced unit') from None
        pos = np.searchsorted(free, action.cell)
        if pos >= len(free) or free[pos] != action.cell:
            raise RadError(f'cell {action.cell} is not a free cell')
        return (u * len(free) + int(pos)) * 4 + action.rotation

    def decode(self, index: int) -> Action:
        units, free = self.unplaced_units(), self.free_cells()
        n = len(units) * len(free) * 4
        if not 0 <= index <= n:
            raise RadError(f'action index {index} is outside 0..{n}')
        if index == n:
            return TERMINATE
        rest, rotation = divmod(index, 4)
        u, pos = divmod(rest, len(free))
        return Action(units[u][0], units[u][1], int(free[pos]), rotation)

    # ---- dynamics --------------------------------------------------------
    def resulting_cells(self, action: Action) -> tuple[np.ndarray | None, int]:
        """Grid cells (in unit order) the block would occupy, and its new yaw.

        Cells is None when some unit would land off the grid.
        """
        b = action.block
        yaw = (self._current_yaw(b) + 90 * action.rotation) % 360
        key = (self.scene.blocks[b].type, yaw, action.unit, action.cell)
        if key not in self._cells_of:
            offsets = self.types[b].rotated(yaw)
            rel = offsets - offsets[action.unit]
            cells = self.grid.cells_at(self.grid.centres[action.cell] + self.scene.pitch * rel)
            if cells is not None:
                cells.flags.writeable = False
            self._cells_of[key] = cells
        return self._cells_of[key], yaw

    def _current_yaw(self, b: int) -> int:
        return self.state.placed[b][1] if b in self.state.placed else self.yaws[b]

    def _check_action(self, action: Action) -> None:
        n_blocks = len(self.scene.blocks)
        if not 0 <= action.block < n_blocks:
            raise RadError(f'block index {action.block} is outside 0..{n_blocks - 1}')
        if not 0 <= action.unit < self.types[action.block].size:
            raise RadError(f'unit {action.unit} is not a unit of block {self.scene.blocks[action.block].id!r}')
        if not 0 <= action.cell < self.grid.num_cells:
            raise RadError(f'cell {action.cell} is outside 0..{self.grid.num_cells - 1}')
        if action.rotation not in (0, 1, 2, 3):
            raise RadError(f'rotation {action.rotation} is not one of 0, 1, 2, 3')

    def evaluate(self, action: Action) -> tuple[Outcome | None, str, np.ndarray | None, int]:
        """Why the action would be invalid now (None if it is valid), without acting."""
        self._check_action(action)
        b = action.block
        if b in self.state.placed:
            return Outcome.INVALID_BLOCK, f'block {self.scene.blocks[b].id!r} is already placed', None, 0
        if self.scene.feeder is not None and self.scene.feeder.order == 'queue':
            takeable, later = feeder_blocks(self.scene, self.state.placed)
            if b in later:
                front = ', '.join(self.scene.blocks[k].id for k in takeable)
                return (Outcome.INVALID_BLOCK, f'block {self.scene.blocks[b].id!r} is still in the feeder\'s queue '
                        f'(it offers {front} now)', None, 0)
        cells, yaw = self.resulting_cells(action)
        if cells is None:
            return Outcome.INVALID_OFF_GRID, 'a unit would land outside the target regions', None, yaw
        taken = self.state.occupancy[cells] >= 0
        if taken.any():
            other = self.scene.blocks[int(self.state.occupancy[cells][taken][0])].id
            return Outcome.INVALID_OVERLAP, f'overlaps placed block {other!r}', cells, yaw
        stable, reason = self._stable(b, cells)
        if not stable:
            return Outcome.INVALID_UNSTABLE, reason, cells, yaw
        return None, '', cells, yaw

    def _stable(self, b: int, cells: np.ndarray) -> tuple[bool, str]:
        mode = self.config.stability
        if mode == 'none':
            return True, ''
        occ = self.state.occupancy
        if mode == 'support':
            ok = support.fully_supported(self.grid, occ, cells)
            return ok, '' if ok else 'a unit would rest on nothing (support rule)'
        if not support.any_support(self.grid, occ, cells):
            return False, 'the block would rest on nothing and fall'
        if self.grid.clutch is not None:
            key = ('clutch', frozenset((k, tuple(int(c) for c in cs)) for k, (cs, _) in self.state.placed.items()),
                   b, tuple(int(c) for c in cells))
            if key not in self._stability_cache:
                self._stability_cache[key] = self._stands_with_clutch(b, cells)
            return self._stability_cache[key]
        key = (frozenset(tuple(sorted(int(c) for c in cs)) for cs, _ in self.state.placed.values()),
               tuple(int(c) for c in cells))
        if key not in self._stability_cache:
            centres = self.grid.centres
            placed = [centres[cs] for cs, _ in self.state.placed.values()]
            extra = {'clearance': self.scene.clearance} if self.scene.clearance else {}
            if self.scene.course != self.scene.unit:
                extra['course'] = self.scene.course
            self._stability_cache[key] = self.stability(self.scene.unit, placed, centres[cells], **extra)
        return self._stability_cache[key]

    def _stands_with_clutch(self, b: int, cells: np.ndarray) -> tuple[bool, str]:
        """Studded bricks: whether the structure with the new brick stands, forces through contacts and
        studs within their clutch (`domain.statics`), as the twin's joints hold it."""
        placed = list(self.state.placed.items())
        pieces = [np.asarray(cs) for _, (cs, _) in placed] + [np.asarray(cells)]
        verdict = structure_statics(self.grid, pieces, clutch=self.grid.clutch)
        what = 'the structure would fall'
        if verdict:
            # Seating it takes a press (`statics.press_load`): what is built must bear that too.
            load = press_load(self.grid, np.where(self.state.occupancy >= 0, 0, -2), cells, self.grid.clutch)
            if load is None:
                return True, ''
            loads = [None] * (len(pieces) - 1) + [load]
            verdict = structure_statics(self.grid, pieces, clutch=self.grid.clutch, loads=loads)
            if verdict:
                return True, ''
            what = 'pressing it home would break what is built'
        ids = [self.scene.blocks[k].id for k, _ in placed] + [self.scene.blocks[b].id]
        told = verdict.told(lambda n: f'block {ids[n]}', self.scene.studs.mass * GRAVITY)
        return False, f'{what}: ' + '; '.join(f'block {ids[n]} {why}' for n, why in told)

    def fail(self, outcome: Outcome, reason: str, cells: np.ndarray | None = None) -> StepResult:
        """End the episode on an invalid action decided outside the bookkeeping
        (by the robot or by the twin's physics): -1, done."""
        if not outcome.is_invalid:
            raise RadError(f'{outcome.value} is not a failure')
        if self.state.done:
            raise RadError('the episode is over; call reset()')
        self.state.steps += 1
        self.state.done = True
        return StepResult(self.config.invalid_reward, True, outcome, reason, cells)

    def step(self, action: Action) -> StepResult:
        if self.state.done:
            raise RadError('the episode is over; call reset()')
        cfg = self.config
        self.state.steps += 1
        if action.is_terminate:
            self.state.done = True
            return StepResult(0.0, True, Outcome.TERMINATED)
        outcome, reason, cells, yaw = self.evaluate(action)
        if outcome is not None:
            self.state.done = True
            return StepResult(cfg.invalid_reward, True, outcome, reason, cells)
        target = self.grid.is_target[cells]
        reward = cfg.step_reward * (int(target.sum()) - int((~target).sum()))
        self.state.occupancy[cells] = action.block
        self.state.placed[action.block] = (cells, yaw)
        if self.remaining_target_cells() == 0:
            self.state.done = True
            return StepResult(reward + cfg.completion_bonus, True, Outcome.COMPLETED, cells=cells)
        if len(self.state.placed) == len(self.scene.blocks):
            self.state.done = True
            return StepResult(reward, True, Outcome.NO_BLOCKS, cells=cells)
        return StepResult(reward, False, Outcome.PLACED, cells=cells)


def _default_stability(mode: str) -> StabilityCheck | None:
    if mode != 'physics':
        return None
    return PhysicsStability()
