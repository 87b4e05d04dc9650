"""`rad scene from-bricks` and `rad scene check` of brick designs, as a user runs them."""

from pathlib import Path

import pytest
from rad_core.domain.grid import Grid
from rad_core.domain.scene import Scene

from in_process import rad

DESIGNS = Path(__file__).resolve().parents[2] / 'scenes' / 'bricks'


def write(tmp_path, text: str, name: str = 'design.txt') -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_from_bricks_keeps_the_designs_bricks(tmp_path, capsys, monkeypatch):
    out = tmp_path / 'tower.json'
    code, stdout, _ = rad(capsys, monkeypatch, 'scene', 'from-bricks', str(DESIGNS / 'duplo_bridge_tower.ldr'),
                          '--unit', '0.03', '-o', str(out))
    assert code == 0, stdout
    assert '8 duplo bricks, 48 cells on a 30 mm pitch and 36.00 mm courses' in stdout
    scene = Scene.load(out)
    assert scene.studs.system == 'duplo' and scene.course == pytest.approx(0.036)
    assert len(scene.blocks) == 8 and scene.num_target_cells == 48
    assert scene.type_counts() == {'brick2x2': 4, 'brick2x4': 3, 'brick2x2h6': 1}
    grid = Grid(scene)
    assert not any(grid.cell_at(p) is not None for b in scene.blocks for p in scene.unit_positions(b))
    code, stdout, _ = rad(capsys, monkeypatch, 'scene', 'check', str(out))
    assert code == 0 and 'duplo studs (36.00 mm courses' in stdout and 'nothing built' in stdout


def test_check_says_whether_a_design_needs_its_clutch(tmp_path, capsys, monkeypatch):
    design = write(tmp_path, '4x2 (0,0,0)\n4x2 (3,0,1)\n')
    code, stdout, _ = rad(capsys, monkeypatch, 'scene', 'check', design, '--system', 'duplo', '--unit', '0.03')
    assert code == 0
    assert 'stands: every one of its 2 bricks' in stdout
    assert 'without clutch it falls' in stdout and 'tips over the edge' in stdout


def test_a_design_that_falls_even_with_clutch_is_refused_naming_the_brick(tmp_path, capsys, monkeypatch):
    design = write(tmp_path, '4x2 (0,0,0)\n4x2 (3,0,1)\n')
    code, _, err = rad(capsys, monkeypatch, 'scene', 'from-bricks', design, '--system', 'duplo', '--unit', '0.03',
                       '--clutch', '0.5', '-o', str(tmp_path / 'x.json'))
    assert code == 2
    assert 'design.txt:2: the 4x2 brick at (3,0) on course 1: it pulls off its studs' in err
    assert not (tmp_path / 'x.json').exists()
    code, stdout, _ = rad(capsys, monkeypatch, 'scene', 'check', design, '--system', 'duplo', '--unit', '0.03',
                          '--clutch', '0.5')
    assert code == 1 and 'falls' in stdout


def test_a_design_that_tips_on_a_bare_table_stands_on_a_baseplate(tmp_path, capsys, monkeypatch):
    design = write(tmp_path, '2x2 (0,0,0)\n4x2 (1,0,1)\n')        # its weight past the 2 x 2's edge
    common = ('--system', 'duplo', '--unit', '0.03')
    code, stdout, _ = rad(capsys, monkeypatch, 'scene', 'check', design, *common)
    assert code == 1 and 'tips over the edge' in stdout
    code, stdout, _ = rad(capsys, monkeypatch, 'scene', 'check', design, *common, '--baseplate')
    assert code == 0 and 'stands' in stdout
    out = tmp_path / 'x.json'
    code, stdout, _ = rad(capsys, monkeypatch, 'scene', 'from-bricks', design, *common, '--baseplate', '-o', str(out))
    assert code == 0 and 'on a baseplate' in stdout and Scene.load(out).studs.baseplate


@pytest.mark.parametrize('text,args,expected', [
    ('2x4 (0,0,0)\n', (), 'give --system'),
    ('2x4 (0,0)\n', ('--system', 'duplo'), 'design.txt line 1'),
    ('', ('--system', 'duplo'), 'no bricks'),
    ('2x4 (0,0,0)\n', ('--system', 'duplo', '--unit', '2'), '--unit 2.0 m is outside'),
])
def test_bad_designs_get_one_line(tmp_path, capsys, monkeypatch, text, args, expected):
    code, _, err = rad(capsys, monkeypatch, 'scene', 'from-bricks', write(tmp_path, text), *args,
                       '-o', str(tmp_path / 'x.json'))
    assert code == 2 and expected in err and len(err.strip().splitlines()) == 1, err
