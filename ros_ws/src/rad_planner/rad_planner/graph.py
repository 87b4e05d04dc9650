"""Bring the whole rad node graph up with one parameter file, without ros2 launch.

    graph [--params FILE] [--no-viz] [--no-twin] [--sim-time] [-p node.param:=value ...]

Starts, as separate processes, each installed node exactly as `ros2 run` would
(the executable under <prefix>/lib/<package>/), all with the same parameter file
(each node reads its own section), and stops them all together on Ctrl-C. On a full
ROS 2 install, `ros2 launch rad_planner graph.launch.py` does the same. --no-twin starts
every node but the twin, for a real cell (franka_ros2 serves the arm and the hand; see
rad_planner/config/franka.yaml and franka.launch.py). --sim-time runs every node on the twin's
simulated time (the twin publishes /clock; every node gets use_sim_time:=true).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

# (package, executable, node name) of the graph, in start order.
NODES = (
    ('rad_sim', 'twin_node', 'twin'),
    ('rad_planner', 'allocation_node', 'allocation'),
    ('rad_gamp', 'gamp_node', 'gamp'),
    ('rad_planner', 'sequencer_node', 'sequencer'),
    ('rad_planner', 'assembly_node', 'assembly'),
    ('rad_viz', 'viz_node', 'viz'),
    ('rad_viz', 'markers_node', 'markers'),      # RViz's markers
)


def executable(package: str, name: str) -> Path | None:
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix
    try:
        path = Path(get_package_prefix(package)) / 'lib' / package / name
    except PackageNotFoundError:
        return None
    return path if os.access(path, os.X_OK) else None


def default_params() -> Path:
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('rad_planner')) / 'config' / 'graph.yaml'


@dataclass
class Graph:
    """The running node processes; stop() ends them like Ctrl-C would."""

    processes: dict[str, subprocess.Popen]

    def alive(self) -> dict[str, bool]:
        return {name: p.poll() is None for name, p in self.processes.items()}

    def stop(self, timeout: float = 10.0) -> dict[str, int]:
        for p in self.processes.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        deadline = time.monotonic() + timeout
        codes = {}
        for name, p in self.processes.items():
            try:
                codes[name] = p.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                codes[name] = p.wait()
        return codes


def start_graph(params: Path, overrides: dict[str, dict[str, str]] | None = None, viz: bool = True,
                log_dir: Path | None = None, skip: Iterable[str] = ()) -> Graph:
    """Start every node of the graph but those named in skip. overrides: node name -> {param: value}."""
    overrides = overrides or {}
    skip = set(skip)
    processes = {}
    for package, exe, name in NODES:
        if name in skip:
            continue
        path = executable(package, exe)
        if path is None:
            if package == 'rad_viz':
                continue   # the visualizer is optional
            raise RuntimeError(f'{package}/{exe} is not installed: run scripts/setup.sh')
        if name == 'viz' and not viz:
            continue
        argv = [str(path), '--ros-args', '--params-file', str(params)]
        for key, value in overrides.get(name, {}).items():
            argv += ['-p', f'{key}:={value}']
        out = subprocess.DEVNULL
        if log_dir is not None:
            log_dir.mkdir(parents=True, exist_ok=True)
            out = open(log_dir / f'{name}.log', 'wb')
        processes[name] = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                           start_new_session=True)
    return Graph(processes)


def parse_overrides(items: list[str]) -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    for item in items:
        key, sep, value = item.partition(':=')
        node, dot, param = key.partition('.')
        if not sep or not dot:
            raise SystemExit(f'graph: -p expects node.param:=value, got {item!r}')
        out.setdefault(node, {})[param] = value
    return out


def sim_time(overrides: dict[str, dict[str, str]]) -> dict[str, dict[str, str]]:
    """The overrides with every node on simulated time and the twin publishing /clock."""
    out = {name: {'use_sim_time': 'true', **overrides.get(name, {})} for _, _, name in NODES}
    out['twin'] = {'publish_clock': 'true', **out['twin']}
    return {**overrides, **out}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='graph', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--params', type=Path, help='parameter file (default: rad_planner/config/graph.yaml)')
    parser.add_argument('--no-viz', action='store_true', help='do not start the Rerun visualizer')
    parser.add_argument('--no-twin', action='store_true',
                        help='do not start the twin (a real cell: the robot\'s driver serves the arm and the hand)')
    parser.add_argument('--sim-time', action='store_true',
                        help="every node on the twin's simulated time (/clock, use_sim_time)")
    parser.add_argument('--log-dir', type=Path, help='write each node\'s output to DIR/<node>.log')
    parser.add_argument('-p', dest='overrides', action='append', default=[], metavar='NODE.PARAM:=VALUE')
    args = parser.parse_args(argv)
    params = args.params or default_params()
    if not params.is_file():
        print(f'graph: no parameter file {params}', file=sys.stderr)
        return 2
    overrides = parse_overrides(args.overrides)
    if args.sim_time:
        overrides = sim_time(overrides)
    graph = start_graph(params, overrides, viz=not args.no_viz, log_dir=args.log_dir,
                        skip=('twin',) if args.no_twin else ())
    print(f'graph: started {", ".join(graph.processes)} with {params}; Ctrl-C stops them', flush=True)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        while all(graph.alive().values()):
            time.sleep(0.5)
        dead = [n for n, alive in graph.alive().items() if not alive]
        print(f'graph: {", ".join(dead)} exited; stopping the rest', file=sys.stderr)
    except KeyboardInterrupt:
        pass
    codes = graph.stop()
    return 0 if all(c == 0 for c in codes.values()) else 1


if __name__ == '__main__':
    sys.exit(main())
