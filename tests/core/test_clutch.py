"""Studded bricks that lock: a Duplo 2 x 4 cantilevered two studs off a 2 x 2, which stands by its
clutch alone, in the planner's statics, the physics world's stud joints and the twin's press."""

import numpy as np
import pytest
from rad_core.allocation.brick_scenes import built_blocks, lattice_of, scene_from_design, target_of
from rad_core.domain.brick_designs import parse_text
from rad_core.domain.scene import Scene
from rad_core.domain.transforms import yaw_quaternion

CANTILEVER = '4x2 (0,0,0)\n4x2 (3,0,1)\n'
"""A 2 x 4 on the table along x and another on it, one stud column over its end and three out: its
centre of mass a stud beyond the edge. Its two studs must hold about twice its weight: Duplo bricks
scaled to a 3 cm pitch weigh 11.5 g a cell, so about 1 N each (1.06 N with the statics' margin)."""

CLUTCH = 2.0
"""N per stud: Duplo's (`domain.studs.SYSTEMS`)."""


def cantilever_scene(clutch: float | None = None, built: bool = True) -> Scene:
    """The cantilever's scene: the 2 x 2 already built (or on the table), the 2 x 4 on the table."""
    design = parse_text(CANTILEVER, 'cantilever.txt')
    scene, _ = scene_from_design(design, 'duplo', 0.03, CLUTCH)
    doc = scene.to_dict()
    if clutch is not None:
        doc['studs']['clutch'] = clutch       # weaker bricks than the design was checked with
    if not built:
        return Scene.from_dict(doc)
    lattice = lattice_of(design, 'duplo', 0.03, CLUTCH)
    _, region, _ = target_of(design, lattice)
    _, placed = built_blocks(design.normalised(), lattice, region)
    base = doc['blocks'][0]                   # both are 2 x 4s: the first is the base
    base['position'], base['yaw'] = list(placed[0].position), placed[0].yaw
    return Scene.from_dict(doc)


def top_pose(scene: Scene):
    design = parse_text(CANTILEVER, 'cantilever.txt')
    lattice = lattice_of(design, 'duplo', 0.03, CLUTCH)
    _, region, _ = target_of(design, lattice)
    _, placed = built_blocks(design.normalised(), lattice, region)
    top = scene.blocks[1]
    return top.id, np.asarray(placed[1].position), placed[1].yaw


def test_the_cantilever_stands_by_clutch_alone():
    from rad_core.allocation.brick_scenes import design_verdict
    design = parse_text(CANTILEVER, 'cantilever.txt')
    assert design_verdict(design, lattice_of(design, 'duplo', 0.03, CLUTCH))[0] == 'stands'
    verdict, why = design_verdict(design, lattice_of(design, 'duplo', 0.03, CLUTCH), clutch=False)
    assert verdict == 'falls' and 'tips over the edge' in why
    verdict, why = design_verdict(design, lattice_of(design, 'duplo', 0.03, 0.5))
    assert verdict == 'falls' and 'cantilever.txt:2' in why
    assert 'pulls off its studs' in why and 'must hold 2.11 N over 2 studs, the clutch gives 1.00 N' in why


def _settled(world, block_id: str, seconds: float = 1.0) -> float:
    """How far (m) the block moved while the world ran `seconds`."""
    before, _ = world.block_pose(block_id)
    world.step(int(seconds / world.config.physics.time_step))
    after, _ = world.block_pose(block_id)
    return float(np.linalg.norm(after - before))


@pytest.mark.parametrize('joined,clutch,stays', [(True, None, True), (False, None, False), (True, 0.5, False)])
def test_stud_joints_hold_the_cantilever_up_to_their_clutch(joined, clutch, stays):
    from rad_core.sim.world import World
    scene = cantilever_scene(clutch)
    top, position, yaw = top_pose(scene)
    with World(scene) as world:
        world.set_block_pose(top, position, yaw_quaternion(yaw))
        if joined:
            assert world.studs.join(world, top) == [scene.blocks[0].id]
            assert len(world.studs.studs) == 2            # one stud column of two studs over the 2 x 2
        moved = _settled(world, top)
        assert (moved < 0.001) == stays, moved
        assert bool(world.studs.broken) == (joined and not stays)


def test_joints_made_inside_a_snapshot_are_gone_after_it():
    from rad_core.sim.world import World
    scene = cantilever_scene()
    top, position, yaw = top_pose(scene)
    with World(scene) as world:
        with world.preserved():
            world.set_block_pose(top, position, yaw_quaternion(yaw))
            world.studs.join(world, top)
            assert world.studs.studs
        assert not world.studs.studs
        assert world.pybullet.getNumConstraints(physicsClientId=world.client) == 0


@pytest.mark.parametrize('press_depth,joined', [(0.003, True), (0.0, False)])
def test_the_twin_joins_a_brick_only_when_the_arm_presses_it_home(press_depth, joined):
    from rad_core.gamp.action import MotionPlanner, SceneAction
    from rad_core.gamp.planner import GampConfig
    from rad_core.sim.twin import Twin, twin_world_config
    from rad_core.sim.world import World, WorldConfig

    scene = cantilever_scene()
    top, position, yaw = top_pose(scene)
    planner = MotionPlanner(GampConfig(press_depth=press_depth))
    try:
        region = scene.targets[0]
        cell = tuple(int(v) for v in np.round((position - np.asarray(region.origin)) / scene.pitch))
        block = scene.block(top)
        result, planned, _ = planner(scene, SceneAction(top, 0, region.name, cell, ((yaw - block.yaw) // 90) % 4))
    finally:
        planner.close()
    assert result.success, result.reason
    assert planned == pytest.approx(position)
    with World(scene, twin_world_config(WorldConfig())) as world:
        twin = Twin(world)
        assert twin.execute_motion(result.motion) == ''
        twin.settle(1.0)
        assert bool(world.studs.studs) == joined
        now, _ = world.block_pose(top)
        assert (float(np.linalg.norm(now - position)) < 0.002) == joined


def _env_after(text: str, built: int, clutch: float | None = None):
    """The MDP of a design's scene with its first `built` bricks placed where the design has them,
    and the design's next brick as an action (block, cells)."""
    from rad_core.env.mdp import AssemblyEnv, EnvConfig
    design = parse_text(text, 'design.txt')
    scene, _ = scene_from_design(design, 'duplo', 0.03)
    doc = scene.to_dict()
    if clutch is not None:
        doc['studs']['clutch'] = clutch
    scene = Scene.from_dict(doc)
    lattice = lattice_of(design, 'duplo', 0.03)
    _, region, _ = target_of(design, lattice)
    _, placed = built_blocks(design.normalised(), lattice, region)
    env = AssemblyEnv(scene, EnvConfig(stability='physics'))
    free = {b.type: [] for b in scene.blocks}
    for n, b in enumerate(scene.blocks):
        free[b.type].append(n)
    for k, want in enumerate(placed[:built + 1]):
        b = free[want.type].pop(0)
        cells = env.grid.cells_at(scene.pitch * scene.block_types[want.type].rotated(want.yaw) + want.position)
        if k == built:
            return env, b, cells
        env.state.placed[b] = (cells, want.yaw)
        env.state.occupancy[cells] = b


@pytest.mark.parametrize('clutch,stands', [(None, True), (0.5, False)])
def test_the_mdp_lets_a_brick_reach_out_as_far_as_its_clutch_holds(clutch, stands):
    env, b, cells = _env_after(CANTILEVER, 1, clutch)
    ok, why = env._stable(b, cells)
    assert ok == stands
    assert stands or ('pulls off its studs' in why and 'the clutch gives 1.00 N' in why)


def test_a_press_that_would_break_what_is_built_is_refused():
    # The letter T: the crossbar on its stem; a 2 x 4 pressed onto one arm would lever it off the stem.
    text = '2x2 (3,0,0)\n8x2 (0,0,1)\n4x2 (4,0,2)\n'
    env, b, cells = _env_after(text, 2)
    ok, why = env._stable(b, cells)
    assert not ok and why.startswith('pressing it home would break what is built')
    env, b, cells = _env_after(text, 1)           # the crossbar itself, pressed over the stem: fine
    assert env._stable(b, cells) == (True, '')


@pytest.mark.parametrize('push,stays_joined', [(0.002, True), (0.006, False)])
def test_a_brick_pushed_along_the_one_under_it_keeps_its_studs_until_it_leaves_their_sockets(push, stays_joined):
    """Studs hold sideways by their shape: a joined brick pushed 2 mm along its base comes back to its
    seat with its studs; pushed 6 mm (a fifth of the 3 cm unit) it has left them."""
    from rad_core.sim.world import World
    scene = cantilever_scene()
    top, position, yaw = top_pose(scene)
    with World(scene) as world:
        world.set_block_pose(top, position, yaw_quaternion(yaw))
        world.studs.join(world, top)
        world.step(10)
        world.set_block_pose(top, position + (push, 0.0, 0.0), yaw_quaternion(yaw))
        world.step(int(0.5 / world.config.physics.time_step))
        assert bool(world.studs.broken) == (not stays_joined)
        if stays_joined:
            after, _ = world.block_pose(top)
            assert np.linalg.norm(after - position) < 0.001


@pytest.mark.parametrize('raise_by,unseated', [(0.0, False), (1.0, True), (0.0, None)])
def test_motion_capture_sees_a_brick_standing_on_its_studs_as_not_pressed_home(raise_by, unseated):
    """A Duplo brick a stud's height (8.4 mm at a 3 cm pitch) above its seat registers on its seat, marked
    not pressed home; on its seat, or on the table (None: which has no studs), it is not marked."""
    from rad_core.cell.mocap import RegistrationConfig, RigidBodyPose, register_world
    scene = cantilever_scene()
    top, position, yaw = top_pose(scene)
    stud = scene.stud_height
    assert stud == pytest.approx(0.03 * 4.5 / 16)
    base = scene.blocks[0]
    where = np.asarray(position) if unseated is not None else np.array([0.3, -0.3, scene.course / 2])
    bodies = [RigidBodyPose(base.id, tuple(base.position), tuple(yaw_quaternion(base.yaw))),
              RigidBodyPose(top, tuple(where + (0, 0, raise_by * stud)), tuple(yaw_quaternion(yaw)))]
    config = RegistrationConfig(body_map={b.id: (b.id, b.type) for b in scene.blocks})
    reg = register_world(bodies, scene, config)
    assert not reg.set_aside
    assert (top in reg.unseated) == bool(unseated)
    assert reg.scene.block(top).position[2] == pytest.approx(where[2])
    if unseated:
        assert reg.unseated[top] == pytest.approx(stud, abs=1e-4)


def _tower_build(**faults):
    """A Duplo tower of three 2 x 4s built by the robot in the twin with these faults."""
    from rad_core.experiment.evaluation import get_agent, robot_planner
    from rad_core.sequencing.execution.twin_build import build_simulated
    from rad_core.sim.faults import FaultConfig
    from rad_core.sim.twin import TwinConfig
    design = parse_text('4x2 (0,0,0)\n4x2 (0,0,1)\n4x2 (0,0,2)\n', 'tower.txt')
    scene, _ = scene_from_design(design, 'duplo', 0.03)
    planner = robot_planner(get_agent('default'))
    try:
        return build_simulated(scene, lambda now, start: planner(now, start, 0), planner.motion,
                               twin_config=TwinConfig(faults=FaultConfig(**faults)))
    finally:
        planner.close()


@pytest.mark.slow
def test_a_brick_not_pressed_home_is_seen_and_pressed_again():
    built = _tower_build(seed=1, unpressed=0.5)
    assert built.injected == {'unpressed': 1}
    result = built.result
    assert result.success and result.coverage == 1.0 and not result.unseated
    fault, = result.faults
    assert 'is not pressed home: motion capture sees it 8.4 mm above its seat' in fault['problem']
    assert fault['recovered']
    assert len(result.steps) == 4           # three bricks, one of them taken again and pressed


@pytest.mark.slow
def test_a_brick_left_unpressed_fails_the_run_naming_it():
    built = _tower_build(seed=0, unpressed=0.5)        # the top brick three times in a row
    result = built.result
    assert not result.success and result.reason.startswith('not pressed home: ')
    assert all(not f['recovered'] for f in result.faults)


def test_a_studded_scene_is_stepped_in_shorter_steps_and_a_plain_one_as_before():
    from rad_core.domain.errors import RadError
    from rad_core.sim.world import World, WorldConfig
    studded = cantilever_scene()
    doc = studded.to_dict()
    doc.pop('studs')
    plain = Scene.from_dict(doc)
    with World(plain) as world:
        p, cid, cfg = world.pybullet, world.client, world.config

        def bullet():
            got = p.getPhysicsEngineParameters(physicsClientId=cid)
            return got['fixedTimeStep'], got['numSolverIterations']

        before = bullet()
        assert world.substeps == 1 and before == (cfg.physics.time_step, cfg.physics.solver_iterations)
        world.load_scene(studded)
        assert world.substeps == cfg.stud_substeps > 1
        assert bullet() == pytest.approx((cfg.physics.time_step / cfg.stud_substeps, cfg.stud_solver_iterations))
        world.load_scene(plain)
        assert world.substeps == 1 and bullet() == before
    with pytest.raises(RadError, match='stud_substeps'):
        WorldConfig(stud_substeps=0)


def test_the_scene_keeps_the_designs_bricks_as_its_design():
    from rad_core.sequencing.agent.stages import design_allocation
    scene = cantilever_scene(built=False)
    region = scene.targets[0]
    assert [p.type for p in scene.design] == [b.type for b in scene.blocks]
    assert sorted(c for p in scene.design for c in p.cells) == sorted(region.filled)
    assert [min(c[2] for c in p.cells) for p in scene.design] == [0, 1]      # the file's order
    # With the base built, what is left of the design is the top brick.
    assert [p.cells for p in design_allocation(cantilever_scene()).placements] == [scene.design[1].cells]


TIPPING = '2x2 (0,0,0)\n4x2 (1,0,1)\n'
"""A 2 x 4 on a 2 x 2 one stud column in and three out: together their weight lies past the 2 x 2's
edge, so the pair tips over on a bare table; a baseplate's studs hold the 2 x 2 down."""


@pytest.mark.parametrize('baseplate', [False, True])
def test_a_baseplate_holds_down_what_would_tip_over_on_a_bare_table(baseplate):
    from rad_core.allocation.brick_scenes import design_verdict
    design = parse_text(TIPPING, 'tipping.txt')
    verdict, why = design_verdict(design, lattice_of(design, 'duplo', 0.03, CLUTCH, baseplate=baseplate))
    assert verdict == ('stands' if baseplate else 'falls'), why
    if not baseplate:
        assert 'tips over the edge' in why


@pytest.mark.parametrize('baseplate', [False, True])
def test_a_brick_pressed_onto_a_baseplate_is_joined_to_the_table_and_holds_there(baseplate):
    from rad_core.sim.clutch import TABLE
    from rad_core.sim.world import World
    design = parse_text(TIPPING, 'tipping.txt')
    scene, lines = scene_from_design(design, 'duplo', 0.03, CLUTCH, baseplate=True)   # refused on a bare table
    assert scene.studs.baseplate and 'on a baseplate' in lines[0]
    if not baseplate:
        doc = scene.to_dict()
        del doc['studs']['baseplate']
        scene = Scene.from_dict(doc)
    lattice = lattice_of(design, 'duplo', 0.03, CLUTCH, baseplate=baseplate)
    _, region, _ = target_of(design, lattice)
    _, placed = built_blocks(design.normalised(), lattice, region)
    with World(scene) as world:
        ids = {}
        for at in placed:           # each supply brick of the design's type where the design has it
            block = next(b for b in scene.blocks if b.type == at.type)
            world.set_block_pose(block.id, at.position, yaw_quaternion(at.yaw))
            ids[at.type] = block.id
        base, top = ids['brick2x2'], ids['brick2x4']
        assert world.studs.join(world, base) == ([TABLE] if baseplate else [])
        assert world.studs.join(world, top) == [base]
        assert len(world.studs.studs) == (4 if baseplate else 0) + 2      # 2 x 2 studs under the base
        moved = _settled(world, top)
        assert (moved < 0.001) == baseplate, moved


def test_a_sleeping_brick_moved_by_the_twin_wakes_and_falls():
    from rad_core.sim.world import World, WorldConfig
    from rad_core.domain.errors import RadError
    scene = cantilever_scene()
    top, position, yaw = top_pose(scene)
    with World(scene) as world:
        world.set_block_pose(top, position, yaw_quaternion(yaw))
        world.studs.join(world, top)
        assert _settled(world, top, 3.0) < 0.001               # still for 3 s: asleep (`stud_sleep`)
        world.studs.let_go(world, top)
        lifted = position + (0.0, 0.0, 0.05)
        world.set_block_pose(top, lifted, yaw_quaternion(yaw))
        world.step(int(0.5 / world.config.physics.time_step))
        assert world.block_pose(top)[0][2] < lifted[2] - 0.04      # it fell back down, not hung in the air
    with pytest.raises(RadError, match='stud_sleep'):
        WorldConfig(stud_sleep=-1.0)
