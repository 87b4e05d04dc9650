"""The statics and the physics twin judge tiny studded-brick structures alike, through the core of
benchmarks/bench_statics_twin.py: a cantilever its clutch holds stands in both (and falls in both
without clutch), one too long for its clutch falls in both, a brick over nothing falls in both."""

import importlib.util
import sys
from pathlib import Path

import pytest
from rad_core.domain.brick_designs import parse_text
from rad_core.domain.statics import FLOATS

BENCH = Path(__file__).resolve().parents[2] / 'benchmarks' / 'bench_statics_twin.py'


@pytest.fixture(scope='module')
def bench():
    spec = importlib.util.spec_from_file_location('bench_statics_twin', BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)      # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return sys.modules[spec.name]


@pytest.fixture(scope='module')
def twin(bench):
    with bench.Twin() as world:
        yield world


def judged(bench, twin, text: str, clutch: bool = True):
    """(the layout, the statics' verdict, the twin's) on the whole design, Duplo at a 3 cm pitch."""
    lay = bench.layout(parse_text(text, 'design.txt', 'design'), 'duplo', 0.03)
    order, _ = bench.build_order(lay)
    return (lay, *bench.judge(lay, order, twin, clutch))


def test_a_cantilever_its_clutch_holds_stands_in_both_and_falls_in_both_without_clutch(bench, twin):
    # A 2 x 4 three studs out over the end of another: its two studs hold about 1.06 N each of 2 N.
    text = '4x2 (0,0,0)\n4x2 (3,0,1)\n'
    lay, statics, physics = judged(bench, twin, text)
    assert statics.stands and physics.stands, (statics, physics)
    assert physics.moved < bench.MOVE_TOL * lay.scene.unit and physics.broken == 0
    lay, statics, physics = judged(bench, twin, text, clutch=False)
    assert not statics.stands and not physics.stands
    assert statics.falling == physics.falling == (1,)


def test_a_cantilever_too_long_for_its_clutch_falls_in_both(bench, twin):
    # A 2 x 8 on one stud column of a two-course base, seven studs out: its two studs would have to
    # hold about 6 N each, the clutch gives 2 N.
    lay, statics, physics = judged(bench, twin, '6x2 (0,0,0)\n6x2 (0,0,1)\n8x2 (5,0,2)\n')
    assert not statics.stands and statics.falling == (2,) and 'pulls off its studs' in statics.why[0]
    assert not physics.stands and physics.falling == (2,) and physics.broken > 0


def test_a_brick_resting_on_nothing_falls_in_both(bench, twin):
    lay, statics, physics = judged(bench, twin, '2x2 (0,0,0)\n2x2 (0,0,2)\n')
    assert not statics.stands and statics.falling == (1,) and statics.why == (FLOATS,)
    assert not physics.stands and physics.falling == (1,)


def test_a_tall_thin_lego_column_stands_in_both_with_studs_and_without(bench, twin):
    # The stem of a T: 16 LEGO 2 x 4s in one column, 31 cm high on a 3.2 cm wide foot. At one 1/240 s
    # Bullet step a time it rocked over (22 mm within 0.4 s, with or without stud joints); the twin
    # steps studded scenes shorter (`WorldConfig.stud_substeps`).
    text = ''.join(f'4x2 (0,0,{z})\n' for z in range(16))
    lay = bench.layout(parse_text(text, 'column.txt', 'column'), 'lego', bench.LEGO_UNIT)
    order, _ = bench.build_order(lay)
    for clutch in (True, False):
        statics, physics = bench.judge(lay, order, twin, clutch)
        assert statics.stands and physics.stands, (clutch, statics, physics)
        assert physics.moved < bench.MOVE_TOL * lay.scene.unit / 2
