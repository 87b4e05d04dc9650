"""The README's main job, as a user runs it: `rad demo` brings up the graph and builds."""

import json
import shutil
import subprocess

from rad_core.domain.scene import Scene


def chunk_kinds(png: bytes) -> list[bytes]:
    """The kinds of a PNG file's chunks, in order."""
    assert png[:8] == b'\x89PNG\r\n\x1a\n'
    kinds, pos = [], 8
    while pos < len(png):
        kinds.append(png[pos + 4:pos + 8])
        pos += 12 + int.from_bytes(png[pos:pos + 4], 'big')
    return kinds


def test_rad_demo_builds_the_default_scene_and_writes_every_output(tmp_path):
    exe = shutil.which('rad')
    assert exe, 'rad is not on PATH (source scripts/env.sh)'
    out = tmp_path / 'demo'
    r = subprocess.run([exe, 'demo', '--out', str(out), '--rtf', '8'], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert 'demo: built: 4 steps' in r.stdout and 'coverage 1.00' in r.stdout
    for name in ('scene.json', 'result.json', 'before.png', 'after.png', 'build.png', 'recording.rrd'):
        assert (out / name).stat().st_size > 0, name
    result = json.loads((out / 'result.json').read_text())
    # The build's animation: the start, then one frame per step.
    assert chunk_kinds((out / 'build.png').read_bytes()).count(b'fcTL') == len(result['steps']) + 1
    assert result['format'] == 'rad-result/1' and result['coverage'] == 1.0
    scene = Scene.from_dict(result['scene'])
    assert scene.to_dict() == Scene.load(out / 'scene.json').to_dict()
    # final_blocks are valid blocks of the scene's format, four of them on the grid now.
    final = Scene.from_dict(dict(result['scene'], blocks=result['final_blocks']))
    moved = [b for b, b0 in zip(final.blocks, scene.blocks) if b.position != b0.position]
    assert len(moved) == 4 and len(result['steps']) == 4
    verify = subprocess.run([shutil.which('rerun'), 'rrd', 'verify', str(out / 'recording.rrd')],
                            capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr


def test_rad_demo_refuses_a_bad_scene_file(tmp_path):
    bad = tmp_path / 'bad.json'
    bad.write_text('{"format": "rad-scene/1"}')
    r = subprocess.run([shutil.which('rad'), 'demo', '--scene', str(bad), '--out', str(tmp_path / 'o')],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "demo: error: missing field 'block_types'" in r.stderr


def test_demo_refuses_bad_faults_and_cycles_before_starting_the_graph(tmp_path):
    """--faults and --cycles are checked first: a one-line reason, exit code 2, no node started."""
    from ros_harness import INSTALL_DIR
    exe = INSTALL_DIR / 'rad_planner' / 'lib' / 'rad_planner' / 'demo'
    bad = tmp_path / 'faults.json'
    bad.write_text('{"slipp": 0.1}')
    for args, expected in ((['--faults', str(tmp_path / 'none.json')], 'is neither none, realistic nor a file'),
                           (['--faults', str(bad)], 'unknown fault setting(s) slipp'),
                           (['--cycles', '0'], '--cycles must be at least 1')):
        r = subprocess.run([str(exe), '--out', str(tmp_path / 'o'), *args], capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 2 and expected in r.stderr, r.stderr
        assert not (tmp_path / 'o' / 'logs').exists()
