import dataclasses
import json

import numpy as np
import pytest
from rad_core.allocation import AllocationParams, solve, validate_allocation
from rad_core.allocation.highs import solve_highs
from rad_core.domain.blocks import DEFAULT_LIBRARY
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene

from scenes import U, doc, scene


def random_scene(seed: int) -> Scene:
    """Random regions (up to 3, up to 4x3x4), random target cells, random block heap."""
    rng = np.random.default_rng(seed)
    targets = []
    for r in range(int(rng.integers(1, 4))):
        size = [int(rng.integers(1, 5)), int(rng.integers(1, 4)), int(rng.integers(1, 5))]
        cells = [[i, j, k] for i in range(size[0]) for j in range(size[1]) for k in range(size[2])
                 if rng.random() < 0.5] or [[0, 0, 0]]
        targets.append({'name': f'r{r}', 'origin': [0.3 + 0.3 * r, 0.3, U / 2], 'size': size, 'filled': cells})
    names = list(DEFAULT_LIBRARY)
    blocks = []
    for n in range(int(rng.integers(1, 9))):
        blocks.append({'id': f'b{n}', 'type': str(rng.choice(names)), 'position': [0.2 + 0.3 * (n % 4),
                       -0.2 - 0.3 * (n // 4), U / 2], 'yaw': int(rng.choice([0, 90, 180, 270]))})
    types = {n: [list(o) for o in DEFAULT_LIBRARY[n].offsets] for n in names}
    return Scene.from_dict(doc(blocks=blocks, targets=targets, types=types))


@pytest.mark.parametrize('seed', range(60))
def test_cpsat_optimum_matches_highs_on_random_scenes(seed):
    s = random_scene(seed)
    a = solve(s, AllocationParams(time_limit_s=20))
    b = solve_highs(s, time_limit_s=20)
    assert a.status == 'OPTIMAL' and b.status == 'OPTIMAL'
    assert a.objective == pytest.approx(b.objective)
    assert a.bound == pytest.approx(a.objective)
    assert validate_allocation(s, a) == []
    assert validate_allocation(s, b) == []


@pytest.mark.parametrize('grid', [3, 4, 5, 6])
def test_generated_scenes_can_be_filled_perfectly(grid):
    for seed in range(5):
        s = generate_scene(GeneratorConfig(grid=grid), seed)
        a = solve(s)
        assert a.status == 'OPTIMAL'
        # The generator lays out a tiling of the target, so c^T g reaches N_F.
        assert a.objective == s.num_target_cells
        assert validate_allocation(s, a) == []


def test_counts_limit_and_objective_tradeoff():
    # Target: a row of 3; only one I2 and no cubes -> best is the I2 (objective 2).
    s = scene(blocks=[{'id': 'i0', 'type': 'I2', 'position': [0.6, -0.2, U / 2], 'yaw': 0}])
    a = solve(s)
    assert a.objective == 2 and len(a.placements) == 1 and a.placements[0].type == 'I2'
    assert all(c[2] == 0 for c in a.placements[0].cells)


def test_non_target_cells_cost_one_each():
    # A single L3_up can cover 2 target cells + 1 non-target ([1,0,1] is not a target) or
    # the L's corner on [0,0,0],[1,0,0],[0,0,1]: all three targets -> objective 3.
    s = scene(blocks=[{'id': 'l0', 'type': 'L3_up', 'position': [0.6, -0.2, U / 2], 'yaw': 0}])
    a = solve(s)
    assert a.objective == 3
    assert sorted(a.placements[0].cells) == [(0, 0, 0), (0, 0, 1), (1, 0, 0)]


def test_deterministic_for_a_fixed_seed():
    s = generate_scene(GeneratorConfig(grid=6), 3)
    first = solve(s, AllocationParams(seed=7))
    for _ in range(3):
        again = solve(s, AllocationParams(seed=7))
        assert again.placements == first.placements
        assert again.objective == first.objective


def test_placed_blocks_occupy_cells_and_do_not_count():
    d = doc()
    d['blocks'][0]['position'] = [0.45, 0.1, U / 2]     # c0 sits on target cell [0,0,0]
    s = Scene.from_dict(d)
    a = solve(s)
    assert validate_allocation(s, a) == []
    assert all((0, 0, 0) not in p.cells for p in a.placements)
    assert sum(p.type == 'cube' for p in a.placements) <= 1   # one cube left on the table
    assert a.objective == 3


def test_time_limit_is_honoured_and_bound_reported():
    # A big random target with more blocks than it needs: the greedy start is not optimal.
    rng = np.random.default_rng(0)
    size = (10, 4, 10)
    targets = [{'name': 'big', 'origin': [0.3, 0.3, U / 2], 'size': list(size),
                'filled': [[i, j, k] for i in range(size[0]) for j in range(size[1]) for k in range(size[2])
                           if rng.random() < 0.6]}]
    names = ['T4', 'S4_up', 'L3', 'L3_up', 'T4_up', 'O4_up', 'I3']
    blocks = [{'id': f'b{n}', 'type': names[n % len(names)], 'position': [-1 + 0.15 * (n % 12),
               -0.3 - 0.2 * (n // 12), U / 2], 'yaw': 0} for n in range(120)]
    types = {n: [list(o) for o in DEFAULT_LIBRARY[n].offsets] for n in names}
    s = Scene.from_dict(doc(blocks=blocks, targets=targets, types=types))
    full = solve(s, AllocationParams(time_limit_s=60))
    assert full.status == 'OPTIMAL'
    a = solve(s, AllocationParams(time_limit_s=0.001))
    assert a.solve_time_s < full.solve_time_s
    # Stopped before CP-SAT proved anything: the best found so far and a valid bound.
    assert a.status == 'FEASIBLE'
    assert 0 < a.objective < full.objective <= a.bound
    assert validate_allocation(s, a) == []


@pytest.mark.parametrize('params,msg', [
    (AllocationParams(time_limit_s=0), 'time_limit_s must be a positive'),
    (AllocationParams(time_limit_s=float('nan')), 'time_limit_s'),
    (AllocationParams(num_workers=0), 'num_workers'),
    (AllocationParams(seed=-1), 'seed'),
])
def test_bad_parameters_are_refused(params, msg):
    with pytest.raises(RadError, match=msg):
        solve(scene(), params)


def test_validator_catches_each_kind_of_error():
    s = scene()
    good = solve(s)
    assert validate_allocation(s, good) == []
    p0 = good.placements[0]
    cases = {
        'objective': dataclasses.replace(good, objective=good.objective + 1),
        'already occupied': dataclasses.replace(good, placements=good.placements + (p0,)),
        'unknown block type': dataclasses.replace(good, placements=(dataclasses.replace(p0, type='Q'),)),
        'unknown target region': dataclasses.replace(good, placements=(dataclasses.replace(p0, target='x'),)),
        'outside the region box': dataclasses.replace(good, placements=(dataclasses.replace(
            p0, cells=tuple((c[0] + 5, c[1], c[2]) for c in p0.cells)),)),
        'not the block shape': dataclasses.replace(good, placements=(dataclasses.replace(
            p0, type='I2', yaw=0, cells=((0, 0, 0), (2, 0, 0))),)),
        'below the objective': dataclasses.replace(good, bound=good.objective - 1),
    }
    for expected, bad in cases.items():
        problems = validate_allocation(s, bad)
        assert any(expected in p for p in problems), (expected, problems)
    too_many = dataclasses.replace(good, placements=tuple(
        dataclasses.replace(p0, type='I2', yaw=0, cells=((0, 0, k), (1, 0, k))) for k in range(2)), objective=1)
    assert any('only 1 blocks available' in p for p in validate_allocation(s, too_many))


def test_result_json_round_trip():
    from rad_core.allocation import AllocationResult
    a = solve(scene())
    doc_ = a.to_dict()
    assert doc_['format'] == 'rad-allocation/1'
    assert set(doc_) == {'format', 'status', 'objective', 'bound', 'solve_time_s', 'placements'}
    assert AllocationResult.from_dict(doc_).placements == a.placements


def test_solving_leaves_the_process_sigint_handling_alone():
    # CP-SAT's own SIGINT catcher used to leave SIGINT at its default action, so
    # a node that had solved once died by Ctrl-C instead of shutting down.
    import subprocess
    import sys
    # The child starts with Python's own SIGINT handler even when this run was started in the
    # background (a shell's & makes children ignore SIGINT, and Python then keeps it ignored).
    code = ('import os, signal, time, json\n'
            'signal.signal(signal.SIGINT, signal.default_int_handler)\n'
            'from rad_core.allocation import solve\n'
            'from rad_core.domain.scene import Scene\n'
            f'solve(Scene.loads({json.dumps(doc())!r}))\n'
            'try:\n'
            '    os.kill(os.getpid(), signal.SIGINT)\n'
            '    time.sleep(2)\n'
            'except KeyboardInterrupt:\n'
            '    print("interrupted cleanly")\n')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and 'interrupted cleanly' in r.stdout, (r.returncode, r.stderr)
