"""Brick designs from generator text and LDraw: the examples, the geometry, and every refusal
naming its line."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from rad_core.domain.brick_designs import (Brick, BrickDesign, BrickDesignError, PARTS, parse_ldraw,
                                           parse_text, read_design)
from rad_core.domain.errors import SceneError

BRICKS = Path(__file__).resolve().parents[2] / 'scenes' / 'bricks'
IDENTITY = '1 0 0 0 1 0 0 0 1'
QUARTER = '0 0 1 0 1 0 -1 0 0'        # 90 degrees about LDraw's vertical axis


def boxes(design: BrickDesign) -> list[tuple[int, ...]]:
    return [b.box for b in design.bricks]


def refusal(reader, text: str, source: str) -> BrickDesignError:
    with pytest.raises(BrickDesignError) as caught:
        reader(text, source)
    return caught.value


# ---- the examples ----------------------------------------------------------------------------

# file: (system, bricks, course_plates, cells, first box, last box); a box is (x, y, z, length, width, height)
EXAMPLES = {
    'staggered_wall.txt': (None, 10, 3, 32, (0, 0, 0, 4, 1, 3), (6, 0, 9, 2, 1, 3)),
    'letter_t.txt': (None, 7, 3, 48, (3, 0, 0, 2, 2, 3), (4, 0, 15, 4, 2, 3)),
    'chair.txt': (None, 20, 3, 60, (0, 0, 0, 1, 1, 3), (0, 3, 24, 4, 1, 3)),
    'duplo_bridge_tower.ldr': ('duplo', 8, 3, 48, (0, 0, 0, 2, 2, 3), (2, 0, 15, 2, 2, 6)),
    'arch_overhang.ldr': ('lego', 10, 1, 150, (0, 0, 0, 2, 2, 3), (10, 0, 16, 1, 2, 1)),
    'gate.mpd': ('lego', 9, 3, 52, (0, 0, 0, 4, 2, 3), (0, 0, 9, 10, 2, 3)),
}


def test_every_example_is_listed_here_and_in_the_readme():
    files = sorted(p.name for p in BRICKS.iterdir() if p.suffix != '.md')
    assert files == sorted(EXAMPLES)
    readme = (BRICKS / 'README.md').read_text()
    assert all(f'`{name}`' in readme for name in files)


@pytest.mark.parametrize('name', sorted(EXAMPLES))
def test_example_reads_as_expected(name):
    system, n, course, cells, first, last = EXAMPLES[name]
    design = read_design(BRICKS / name)
    assert design.name == name.rsplit('.', 1)[0]
    assert design.system == system
    assert len(design.bricks) == n
    assert design.course_plates() == course
    assert len(design.cells()) == cells
    assert design.bricks[0].box == first and design.bricks[-1].box == last
    assert design.overlaps() == []
    assert all(b.source == name for b in design.bricks)


def test_duplo_tower_turns_and_heights():
    design = read_design(BRICKS / 'duplo_bridge_tower.ldr')
    assert boxes(design)[4:] == [(1, 0, 6, 4, 2, 3),     # the bridge over the gap at x = 2
                                 (2, -1, 9, 2, 4, 3),    # turned 90 degrees: 2 along x, 4 along y
                                 (1, 0, 12, 4, 2, 3),    # turned 180 degrees
                                 (2, 0, 15, 2, 2, 6)]    # a 2x2x2: two bricks tall
    assert [b.part for b in design.bricks[4:]] == ['3011', '3011', '3011', '31110']
    assert [b.line for b in design.bricks] == [7, 8, 9, 10, 12, 13, 14, 15]


def test_gate_places_the_post_twice_the_second_turned():
    design = read_design(BRICKS / 'gate.mpd')
    post = [(0, 0, 0, 4, 2, 3), (1, 0, 3, 2, 2, 3), (1, 0, 6, 1, 2, 3), (2, 0, 6, 1, 2, 3)]
    # post.ldr placed at (160, 0, 80) LDU turned 90 degrees: its 2x4 foot runs along y.
    turned = [(8, 0, 0, 2, 4, 3), (8, 1, 3, 2, 2, 3), (8, 2, 6, 2, 1, 3), (8, 1, 6, 2, 1, 3)]
    assert boxes(design) == post + turned + [(0, 0, 9, 10, 2, 3)]
    assert [b.line for b in design.bricks] == [16, 17, 18, 19, 16, 17, 18, 19, 8]


# ---- the model -------------------------------------------------------------------------------

def test_cells_of_a_2x4_at_3_7_0():
    (brick,) = parse_text('2x4 (3,7,0)').bricks
    assert brick.box == (3, 7, 0, 2, 4, 3)
    assert brick.cells(3) == {(3, 7, 0), (3, 8, 0), (3, 9, 0), (3, 10, 0),
                              (4, 7, 0), (4, 8, 0), (4, 9, 0), (4, 10, 0)}
    assert len(brick.cells(1)) == 24 and {k for _, _, k in brick.cells(1)} == {0, 1, 2}


def test_course_plates_is_one_when_plates_mix_with_bricks():
    bricks_only = parse_ldraw(f'1 4 0 -24 0 {IDENTITY} 3001.dat\n1 4 0 -48 0 {IDENTITY} 3001.dat\n', 'a.ldr')
    assert bricks_only.course_plates() == 3
    with_plate = parse_ldraw(f'1 4 0 -24 0 {IDENTITY} 3001.dat\n1 4 0 -32 0 {IDENTITY} 3020.dat\n', 'b.ldr')
    assert boxes(with_plate) == [(-2, -1, 0, 4, 2, 3), (-2, -1, 3, 4, 2, 1)]
    assert with_plate.course_plates() == 1
    assert len(with_plate.cells()) == 8 * 3 + 8


def test_a_brick_off_its_courses_has_no_cells_there():
    brick = Brick(2, 2, 0, 0, 1, 3, '3003', 4, 'x.ldr')
    with pytest.raises(BrickDesignError, match=r'^x\.ldr line 4: 2x2 brick 3003 at \(0,0\) 1 plates up does not '
                                               r'sit on courses of 3 plates$'):
        brick.cells(3)


def test_overlaps_names_each_pair_once():
    a = Brick(2, 2, 0, 0, 0, 1, line=1)
    b = Brick(1, 1, 1, 1, 0, 3, line=2)
    c = Brick(1, 1, 5, 5, 0, 3, line=3)
    d = Brick(4, 4, 0, 0, 2, 1, line=4)
    assert BrickDesign((a, b, c, d)).overlaps() == [(a, b), (b, d)]
    assert BrickDesign((a, c)).overlaps() == []


def test_normalised_shifts_the_least_corner_to_zero():
    design = parse_text('2x2 (-3,5,2)\n1x1 (0,4,3)\n')
    assert boxes(design.normalised()) == [(0, 1, 0, 2, 2, 3), (3, 0, 3, 1, 1, 3)]
    assert design.normalised().normalised() == design.normalised()


# ---- the text format -------------------------------------------------------------------------

def test_text_is_lenient_about_spaces_comments_and_blank_lines():
    text = '\ufeff# a header\n\n  2x4 (3,7,0)  \n1 X 2 ( -1 , 0 , 1 )   # trailing comment\r\n\t3x1(0,0,2)\n'
    design = parse_text(text, 'gen.txt')
    assert boxes(design) == [(3, 7, 0, 2, 4, 3), (-1, 0, 3, 1, 2, 3), (0, 0, 6, 3, 1, 3)]
    assert [b.line for b in design.bricks] == [3, 4, 5]
    assert design.system is None and design.name == 'gen'
    assert all(b.part is None and b.source == 'gen.txt' for b in design.bricks)


def test_text_round_trips_through_write_text():
    text = '2x4 (3,7,0)\n1x2 (-1,0,1)\n1x1 (3,7,1)\n'
    design = parse_text(text, 'r.txt')
    assert design.write_text() == text
    assert parse_text(design.write_text(), 'r.txt') == design


@pytest.mark.parametrize('name', ['chair.txt', 'staggered_wall.txt', 'gate.mpd'])
def test_examples_of_whole_bricks_round_trip_through_text(name):
    design = read_design(BRICKS / name)
    assert boxes(parse_text(design.write_text())) == boxes(design)


def test_write_text_refuses_plates_naming_the_line():
    design = read_design(BRICKS / 'arch_overhang.ldr')
    with pytest.raises(BrickDesignError, match=re.escape(
            'arch_overhang.ldr line 15: the text format holds whole bricks on brick courses only, '
            'not the 8x2 plate 3034 at (0,0) on course 3')):
        design.write_text()


@pytest.mark.parametrize('line, problem', [
    ('2x4 (3,7)', 'the place needs 3 numbers x,y,z, not 2'),
    ('2x4 (3,7,0,1)', 'the place needs 3 numbers x,y,z, not 4'),
    ('2-4 (3,7,0)', "size '2-4' is not HxW"),
    ('2x4 3,7,0', "no place '(x,y,z)'"),
    ('2x4 (3,7,0', "the place has no closing ')'"),
    ('2x4 (3,7,0) red', "'red' after the place"),
    ('2x4 (3,7.5,0)', "'7.5' in the place is not a whole number"),
    ('brick', "no place '(x,y,z)'"),
])
def test_a_malformed_text_line_is_refused_naming_it(line, problem):
    error = refusal(parse_text, f'# design\n1x1 (0,0,0)\n{line}\n', 'gen.txt')
    assert str(error) == (f"gen.txt line 3: {line!r}: {problem}; a line reads 'HxW (x,y,z)', "
                          "such as '2x4 (3,7,0)'")
    assert error.line == 3 and isinstance(error, SceneError)


def test_a_text_brick_of_no_studs_is_refused():
    assert str(refusal(parse_text, '\n0x4 (1,1,1)\n', 'g.txt')) == 'g.txt line 2: size 0x4: a brick is at least 1x1'


def test_overlapping_text_bricks_are_refused_naming_both_lines():
    error = refusal(parse_text, '2x4 (0,0,0)\n# c\n1x1 (5,5,0)\n1x1 (1,3,0)\n', 'o.txt')
    assert str(error) == ("o.txt line 4: the 1x1 brick at (1,3) on course 0 overlaps line 1's "
                          '2x4 brick at (0,0) on course 0')


@pytest.mark.parametrize('text', ['', '\n\n', '# only a comment\n   # another\n'])
def test_an_empty_text_is_refused(text):
    assert str(refusal(parse_text, text, 'empty.txt')) == 'no bricks in empty.txt'


# ---- LDraw -----------------------------------------------------------------------------------

def test_ldraw_frame_and_units_for_lego_and_duplo():
    # A 2x4 brick's origin is the centre of its top face; its long side runs along LDraw x.
    lego = parse_ldraw(f'1 4 40 -24 20 {IDENTITY} 3001.dat\n1 4 40 -48 20 {QUARTER} 3001.dat\n', 'l.ldr')
    assert lego.system == 'lego'
    assert boxes(lego) == [(0, 0, 0, 4, 2, 3), (1, -1, 3, 2, 4, 3)]
    # Duplo: 40 LDU a stud, 48 a brick; design y is LDraw z.
    duplo = parse_ldraw(f'1 4 80 -48 40 {IDENTITY} 3011.dat\n1 4 40 -144 120 {QUARTER} 31111.dat\n', 'd.ldr')
    assert duplo.system == 'duplo'
    assert boxes(duplo) == [(0, 0, 0, 4, 2, 3), (0, 1, 3, 2, 4, 6)]


def test_ldraw_ignores_comments_meta_and_drawing_lines():
    text = ('0 Title\n0 Name: t.ldr\n0 BFC CERTIFY CCW\n\n0 STEP\n'
            '2 24 0 0 0 20 0 0\n3 16 0 0 0 1 0 0 0 0 1\n4 16 0 0 0 1 0 0 1 0 1 0 0 1\n5 24 0 0 0 1 0 0 0 1 0 1 1 1\n'
            f'1 0x2FF0000 10 -8 10 {IDENTITY} 3024.dat\n')
    design = parse_ldraw(text, 't.ldr')
    assert boxes(design) == [(0, 0, 0, 1, 1, 1)] and design.bricks[0].line == 10


@pytest.mark.parametrize('name', ['3001.dat', '3001', '3001.DAT', 'parts\\3001.dat', 'parts/3001.dat', 'S\\3001.dat'])
def test_part_names_in_any_case_with_or_without_dat_or_folder(name):
    design = parse_ldraw(f'1 4 0 -24 0 {IDENTITY} {name}\n', 'n.ldr')
    assert design.bricks[0].part == '3001' and design.bricks[0].box == (-2, -1, 0, 4, 2, 3)


def test_the_part_table_has_the_parts_asked_for():
    lego_bricks = '3005 3004 3622 3010 3009 3008 3003 3002 3001 2456 3007 3006'.split()
    lego_plates = '3024 3023 3623 3710 3666 3460 3022 3021 3020 3795 3034'.split()
    duplo = '3437 87084 3011 2300 4199 2291'.split()
    assert all(PARTS[p].system == 'lego' and PARTS[p].plates == 3 for p in lego_bricks)
    assert all(PARTS[p].system == 'lego' and PARTS[p].plates == 1 for p in lego_plates)
    assert all(PARTS[p].system == 'duplo' and PARTS[p].plates == 3 for p in duplo)
    assert (PARTS['3006'].studs_x, PARTS['3006'].studs_z) == (10, 2)
    assert (PARTS['3004'].studs_x, PARTS['3004'].studs_z) == (2, 1)


def test_mpd_submodel_placed_twice_once_turned_gives_the_corner_studs():
    text = ('0 FILE main.ldr\n'
            f'1 16 0 0 0 {IDENTITY} pair.ldr\n'
            f'1 16 200 -24 100 {QUARTER} Pair.LDR\n'
            '0 FILE pair.ldr\n'
            f'1 4 0 -24 0 {IDENTITY} 3001.dat\n'
            f'1 14 -30 -48 -10 {IDENTITY} 3005.dat\n')
    design = parse_ldraw(text, 'm.mpd')
    # The 1x1 sits over the 2x4's corner at the least x and y; turned, local -x becomes +y.
    assert boxes(design) == [(-2, -1, 0, 4, 2, 3), (-2, -1, 3, 1, 1, 3),
                             (9, 3, 3, 2, 4, 3), (9, 6, 6, 1, 1, 3)]
    assert [b.line for b in design.bricks] == [5, 6, 5, 6]


def test_mpd_submodels_nest_and_compose():
    text = ('0 FILE a.ldr\n'
            f'1 16 100 0 0 {QUARTER} b.ldr\n'
            '0 NOFILE\n0 FILE b.ldr\n'
            f'1 16 0 -24 0 {QUARTER} c.ldr\n'
            '0 FILE c.ldr\n'
            f'1 4 40 -24 20 {IDENTITY} 3001.dat\n')
    # Two quarter turns make a half turn: (40, 20) -> (-40, -20), up two bricks, then x + 100.
    assert boxes(parse_ldraw(text, 'n.mpd')) == [(1, -2, 3, 4, 2, 3)]


def test_unknown_part_is_refused_naming_part_line_and_the_supported():
    error = refusal(parse_ldraw, f'0 x\n1 4 0 -24 0 {IDENTITY} 3001.dat\n1 4 0 -48 0 {IDENTITY} 3039.dat\n', 'u.ldr')
    message = str(error)
    assert message.startswith("u.ldr line 3: unknown part '3039.dat'; supported: LEGO bricks: 3005 (1x1), ")
    assert '3001 (2x4)' in message and 'Duplo bricks: 3437 (2x2)' in message and error.line == 3
    model = str(refusal(parse_ldraw, f'1 4 0 0 0 {IDENTITY} wing.ldr\n', 'w.ldr'))
    assert model.startswith("w.ldr line 1: unknown part 'wing.ldr' (a model not in this file); supported: ")


@pytest.mark.parametrize('matrix, wrong', [
    ('1 0 0 0 0 -1 0 1 0', 'tilted or upside down'),                            # on its side
    ('1 0 0 0 -1 0 0 0 -1', 'tilted or upside down'),                           # upside down
    ('-1 0 0 0 1 0 0 0 1', 'mirrored'),
    ('0.7071 0 0.7071 0 1 0 -0.7071 0 0.7071', 'turned by other than a multiple of 90 degrees, or scaled'),
    ('2 0 0 0 1 0 0 0 1', 'turned by other than a multiple of 90 degrees, or scaled'),
    ('1 0.5 0 0 1 0 0 0 1', 'turned by other than a multiple of 90 degrees, or scaled'),
])
def test_a_part_not_turned_about_the_vertical_by_quarters_is_refused(matrix, wrong):
    error = refusal(parse_ldraw, f'1 4 0 -24 0 {IDENTITY} 3001.dat\n1 4 0 -96 0 {matrix} 3003.dat\n', 't.ldr')
    assert str(error) == (f't.ldr line 2: part 3003 is {wrong}; only turns about the vertical axis by '
                          'multiples of 90 degrees are supported')


def test_a_turn_within_tolerance_is_taken():
    design = parse_ldraw('1 4 0.4 -24 -0.3 0.9999 0 0.001 0 1 0 -0.001 0 0.9999 3001.dat\n', 'ok.ldr')
    assert boxes(design) == [(-2, -1, 0, 4, 2, 3)]


def test_a_tilted_part_in_a_submodel_names_the_placing_line():
    text = ('0 FILE m.ldr\n0 c\n' f'1 16 0 0 0 {IDENTITY} s.ldr\n' '0 FILE s.ldr\n'
            f'1 4 0 -24 0 1 0 0 0 0 -1 0 1 0 3001.dat\n')
    assert str(refusal(parse_ldraw, text, 'm.mpd')).startswith(
        "m.mpd line 5 (in submodel 's.ldr' placed by line 3): part 3001 is tilted or upside down")


@pytest.mark.parametrize('place, what', [
    ('5 -24 0', '-1.750 studs along x'),
    ('0 -24 12', '-0.400 studs along y'),
    ('0 -20 0', '-0.500 plates up'),
])
def test_a_part_off_the_lattice_is_refused_naming_the_line(place, what):
    error = refusal(parse_ldraw, f'0 c\n\n1 4 {place} {IDENTITY} 3001.dat\n', 'off.ldr')
    assert str(error) == f'off.ldr line 3: part 3001: its corner is at {what}, off the lattice'


def test_overlapping_ldraw_parts_are_refused_naming_both_lines():
    text = f'1 4 0 -24 0 {IDENTITY} 3001.dat\n1 4 0 -32 0 {IDENTITY} 3020.dat\n1 4 40 -24 0 {QUARTER} 3020.dat\n'
    assert str(refusal(parse_ldraw, text, 'o.ldr')) == (
        "o.ldr line 3: the 2x4 plate 3020 at (1,-2) 2 plates up overlaps line 1's 4x2 brick 3001 at (-2,-1) "
        'on course 0')


def test_lego_and_duplo_in_one_model_are_refused():
    text = f'1 4 0 -24 0 {IDENTITY} 3001.dat\n1 4 200 -48 0 {IDENTITY} 3437.dat\n'
    assert str(refusal(parse_ldraw, text, 'mix.ldr')) == (
        'mix.ldr line 2: a duplo part in a model whose first part (line 1) is lego; one model holds parts of '
        'one system')


@pytest.mark.parametrize('text, where, problem', [
    ('1 4 0 -24 0 1 0 0 0 1 0 0 0 3001.dat\n', 'line 1', 'a part line reads 1 colour x y z a b c d e f g h i part'),
    ('1 4 0 -24 zero 1 0 0 0 1 0 0 0 1 3001.dat\n', 'line 1', 'a part line reads'),
    ('0 c\n7 4 0 0 0\n', 'line 2', "line type '7': an LDraw line starts with 0 to 5"),
    (f'1 4 0 -24 0 {IDENTITY} 3001.dat\n0 FILE a.ldr\n', 'line 1', "a part before the first '0 FILE' line"),
    ('0 FILE a.ldr\n0 FILE A.ldr\n', 'line 2', "a second model named 'a.ldr'"),
    (f'0 FILE a.ldr\n1 16 0 0 0 {IDENTITY} b.ldr\n0 FILE b.ldr\n1 16 0 0 0 {IDENTITY} a.ldr\n',
     "line 4 (in submodel 'b.ldr' placed by line 2)", "submodel 'a.ldr' contains itself"),
])
def test_malformed_ldraw_is_refused_naming_the_line(text, where, problem):
    assert str(refusal(parse_ldraw, text, 'bad.mpd')).startswith(f'bad.mpd {where}: {problem}')


@pytest.mark.parametrize('text', ['', '0 just a title\n0 Name: e.ldr\n', '0 FILE a.ldr\n2 24 0 0 0 1 1 1\n0 NOFILE\n'])
def test_an_empty_model_is_refused(text):
    assert str(refusal(parse_ldraw, text, 'e.ldr')) == 'no bricks in e.ldr'


def test_read_design_picks_the_reader_by_suffix(tmp_path):
    (tmp_path / 'a.TXT').write_text('\ufeff2x2 (0,0,0)\n')
    (tmp_path / 'b.ldr').write_text(f'1 4 20 -24 20 {IDENTITY} 3003.dat\n')
    (tmp_path / 'c.json').write_text('{}')
    assert boxes(read_design(tmp_path / 'a.TXT')) == [(0, 0, 0, 2, 2, 3)]
    assert read_design(str(tmp_path / 'b.ldr')).bricks[0] == Brick(2, 2, 0, 0, 0, 3, '3003', 1, 'b.ldr')
    with pytest.raises(BrickDesignError, match=r"c\.json: unknown suffix '\.json'; brick designs are \.txt, \.ldr"):
        read_design(tmp_path / 'c.json')
    with pytest.raises(BrickDesignError, match=r'missing\.ldr: cannot be read'):
        read_design(tmp_path / 'missing.ldr')
