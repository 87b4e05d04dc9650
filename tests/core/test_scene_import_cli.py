"""`rad scene from-mesh`, `from-voxels` and `supply` as a user runs them: a mesh becomes a scene
that passes `rad scene check`, allocates fully and plans; bad input is exit code 2 and one line."""

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh
from rad_core.cli import main
from rad_core.domain.scene import Scene
from rad_core.domain.voxels import cells_to_mesh


def letter_t(path) -> str:
    """A T three cells wide and high, one deep, 5 cm cells, in metres."""
    grid = np.zeros((3, 1, 3), dtype=bool)
    grid[:, 0, 2] = True
    grid[1, 0, :] = True
    cells_to_mesh(grid, 0.05).export(path)
    return str(path)


def run(argv, capsys) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.slow   # plans with GAMP (5 s)
def test_from_mesh_gives_a_scene_that_checks_allocates_fully_and_plans(tmp_path, capsys):
    model = letter_t(tmp_path / 'tee.stl')
    out = tmp_path / 'scene.json'
    rc, stdout, _ = run(['scene', 'from-mesh', model, '--unit', 0.05, '--size', 3, '-o', out,
                         '--report', tmp_path / 'report.json'], capsys)
    assert rc == 0 and 'cover all 5 target cells exactly' in stdout
    assert json.loads((tmp_path / 'report.json').read_text())['exact'] is True
    rc, stdout, _ = run(['scene', 'check', out], capsys)
    assert rc == 0 and stdout.startswith('ok:') and '5 target cells' in stdout

    from rad_core.allocation.cpsat import AllocationParams, solve
    from rad_core.domain.coverage import placements_coverage
    scene = Scene.load(out)
    result = solve(scene, AllocationParams(support='stable'))
    assert result.status == 'OPTIMAL' and placements_coverage(scene, result.placements) == 1.0

    from rad_core.sequencing.agent.agent_plan import AgentPlanner
    planner = AgentPlanner('greedy')
    try:
        plan = planner(scene, None)
    finally:
        planner.close()
    assert plan.success and plan.predicted_coverage == 1.0 and len(plan.steps) == len(scene.blocks)


def test_target_only_then_supply_with_an_inventory(tmp_path, capsys):
    model = letter_t(tmp_path / 'tee.obj')
    target = tmp_path / 'target.json'
    rc, stdout, _ = run(['scene', 'from-mesh', model, '--size', 3, '--no-supply', '-o', target], capsys)
    assert rc == 0 and 'no blocks' in stdout
    assert Scene.load(target).blocks == ()
    inventory = tmp_path / 'inventory.json'
    inventory.write_text(json.dumps({'cube': 3}))
    out = tmp_path / 'scene.json'
    rc, stdout, _ = run(['scene', 'supply', target, '--inventory', inventory, '-o', out], capsys)
    assert rc == 0 and '3 of 5 target cells' in stdout and 'warning' in stdout
    assert Scene.load(out).type_counts() == {'cube': 3}
    # Cheapest by costs: the stem of two cubes (2) rather than an I2_up (3); the bar stays an I3, dear as it
    # is (4), since cubes at its ends would stand on nothing.
    rc, stdout, _ = run(['scene', 'supply', target, '--types', 'cube,I3,I2_up', '--objective', 'cheapest',
                         '--cost', 'I3=4,I2_up=3,cube=1', '-o', out], capsys)
    assert rc == 0 and 'cost 6' in stdout
    assert Scene.load(out).type_counts() == {'cube': 2, 'I3': 1}


def test_clearance_is_set_once_and_kept_by_supply(tmp_path, capsys):
    target, out = tmp_path / 'target.json', tmp_path / 'scene.json'
    rc, _, _ = run(['scene', 'from-mesh', letter_t(tmp_path / 't.stl'), '--size', 3, '--no-supply', '--clearance', 0.2,
                    '-o', target], capsys)
    assert rc == 0 and Scene.load(target).clearance == 0.2
    rc, _, _ = run(['scene', 'supply', target, '-o', out], capsys)
    assert rc == 0 and Scene.load(out).clearance == 0.2 and len(Scene.load(out).blocks) == 2
    rc, _, err = run(['scene', 'supply', target, '--clearance', 0.7, '-o', out], capsys)
    assert rc == 2 and 'clearance' in err


def test_from_voxels_with_two_named_regions_back_to_back(tmp_path, capsys):
    face = np.zeros((3, 1, 2), dtype=bool)
    face[:, 0, 0] = True
    face[1, 0, 1] = True
    np.save(tmp_path / 'face.npy', face)
    out = tmp_path / 'scene.json'
    rc, _, _ = run(['scene', 'from-voxels', f'left={tmp_path / "face.npy"}', f'right={tmp_path / "face.npy"}',
                    '--unit', 0.04, '-o', out], capsys)
    assert rc == 0
    scene = Scene.load(out)
    assert [t.name for t in scene.targets] == ['left', 'right'] and scene.unit == 0.04
    assert [t.origin[1] for t in scene.targets] == [0.02, -0.02]
    assert scene.num_target_cells == 8


def test_from_voxels_chooses_blocks_the_hand_can_place_unless_any_order_is_asked(tmp_path, capsys, set_down_hand):
    # The hand that only sets blocks down: with drops (the default) it places either cover.
    step = np.zeros((3, 2, 2), dtype=bool)     # a 3 x 2 floor with a two-cell step on it
    step[:, :, 0] = True
    step[0, :, 1] = True
    np.save(tmp_path / 'step.npy', step)
    reports = {}
    for flags in ([], ['--any-order']):
        report = tmp_path / f'report{len(flags)}.json'
        rc, _, _ = run(['scene', 'from-voxels', tmp_path / 'step.npy', '-o', tmp_path / 'scene.json',
                        '--report', report, *flags], capsys)
        assert rc == 0
        reports[bool(flags)] = json.loads(report.read_text())
    assert reports[False]['exact'] and reports[False]['hand_covered'] == 8
    assert reports[True]['exact'] and reports[True]['hand_covered'] is None
    assert reports[False]['counts'] != reports[True]['counts']


def test_the_scene_goes_to_stdout_and_the_summary_to_stderr(tmp_path, capsys):
    rc, stdout, stderr = run(['scene', 'from-mesh', letter_t(tmp_path / 't.ply'), '--size', 3], capsys)
    assert rc == 0 and Scene.loads(stdout).num_target_cells == 5 and 'exactly' in stderr


@pytest.mark.parametrize('argv, problem', [
    (['scene', 'from-mesh', 'MODEL_FBX'], "unknown mesh format '.fbx'"),
    (['scene', 'from-mesh', 'FLAT_STL', '--scale', '1'], 'flat'),
    (['scene', 'from-mesh', 'BIG_STL', '--scale', '1'], '--scale 0.40 or less'),
    (['scene', 'from-mesh', 'TEE_STL', '--size', '3', '--types', 'I2', '--inventory', 'INV'], 'not both'),
    (['scene', 'from-mesh', 'TEE_STL', '--size', '3', '--types', 'I3'], 'no target cell can be covered'),
    (['scene', 'from-voxels', 'TEE_STL'], "unknown voxel format '.stl'"),
    (['scene', 'supply', 'PLACED'], 'already sit in the target'),
])
def test_bad_input_is_exit_code_2_and_one_line(tmp_path, capsys, argv, problem):
    files = {'MODEL_FBX': tmp_path / 'm.fbx', 'FLAT_STL': tmp_path / 'flat.stl', 'BIG_STL': tmp_path / 'big.stl',
             'TEE_STL': tmp_path / 'tee.stl', 'INV': tmp_path / 'inv.json', 'PLACED': tmp_path / 'placed.json'}
    files['MODEL_FBX'].write_text('x')
    trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], [[0, 1, 2]]).export(files['FLAT_STL'])
    trimesh.creation.box(extents=(1.0, 0.2, 0.3)).export(files['BIG_STL'])
    letter_t(files['TEE_STL'])
    files['INV'].write_text('{"cube": 1}')
    placed = {'format': 'rad-scene/1', 'unit': 0.05, 'block_types': {'cube': [[0, 0, 0]]},
              'blocks': [{'id': 'b0', 'type': 'cube', 'position': [0.5, 0.0, 0.025], 'yaw': 0}],
              'targets': [{'name': 't', 'origin': [0.5, 0.0, 0.025], 'size': [1, 1, 1], 'filled': [[0, 0, 0]]}]}
    files['PLACED'].write_text(json.dumps(placed))
    rc, stdout, stderr = run([str(files.get(a, a)) for a in argv] + ['-o', tmp_path / 'out.json'], capsys)
    assert rc == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('rad: error:') and problem in lines[0], stderr
    assert not (tmp_path / 'out.json').exists()


def test_help_and_scene_check_do_not_load_the_mesh_library(tmp_path):
    code = ('import json, sys\nfrom rad_core.cli import main\n'
            'for argv in (["--help"], ["scene", "from-mesh", "--help"]):\n'
            '    try:\n        main(argv)\n    except SystemExit:\n        pass\n'
            'print(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))\n')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    loaded = set(json.loads(r.stdout.strip().splitlines()[-1]))
    assert loaded.isdisjoint({'trimesh', 'rtree', 'ortools', 'numpy', 'scipy'}), loaded
    assert 'rad_core' in loaded                      # the check sees what was imported


def test_a_model_too_deep_is_turned_a_quarter_and_the_line_says_so(tmp_path, capsys):
    # 4 x 17 x 3 cells at 2 cm: 17 deep exceed the 15 the reach allows across y = 0; turned, 17 wide fit.
    np.save(tmp_path / 'slab.npy', np.ones((4, 17, 3), dtype=bool))
    out = tmp_path / 'slab.json'
    rc, stdout, _ = run(['scene', 'from-voxels', tmp_path / 'slab.npy', '--unit', '0.02', '--no-supply', '-o', out],
                        capsys)
    assert rc == 0
    assert 'turned 90 degrees to fit the reach: 17 cells deep becomes 17 wide' in stdout
    [region] = Scene.loads(out.read_text()).targets
    assert region.size == (17, 4, 3)
    # --yaw 0 fixes the file's orientation, which does not fit: refused in one line naming --yaw 90.
    rc, _, stderr = run(['scene', 'from-voxels', tmp_path / 'slab.npy', '--unit', '0.02', '--yaw', '0',
                         '--no-supply', '-o', tmp_path / 'no.json'], capsys)
    lines = stderr.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and '--yaw 90 fits' in lines[0], stderr
    assert not (tmp_path / 'no.json').exists()


def test_a_tall_tower_moves_nearer_the_robot_and_the_line_says_where(tmp_path, capsys):
    # 12 cells of 5 cm are beyond the reach at x = 0.5 m (11), within it nearer the robot.
    np.save(tmp_path / 'tower.npy', np.ones((2, 2, 12), dtype=bool))
    out = tmp_path / 'tower.json'
    rc, stdout, _ = run(['scene', 'from-voxels', tmp_path / 'tower.npy', '--no-supply', '-o', out], capsys)
    assert rc == 0 and 'nearer the robot' in stdout
    [region] = Scene.loads(out.read_text()).targets
    assert 0.3 < region.origin[0] < 0.5 - 0.025
