"""Test harness for rad's ROS processes: the DDS environment, node processes, services.

Nodes are tested as real processes talking over real DDS on loopback. This module
never imports rclpy at import time: tests/conftest.py must put the DDS settings of
scripts/env.sh into os.environ before anything loads rclpy (and with it Fast DDS).

Typical use from a test (fixtures from tests/conftest.py):

    from ros_harness import call_service, ros_args, wait_for_service
    from rad_msgs.srv import Allocate

    def test_allocate(node_process, ros_node):
        proc = node_process('rad_planner', 'allocation_node', *ros_args({'time_limit_s': 2.0}))
        client = wait_for_service(ros_node, Allocate, 'allocate', timeout=10.0)
        response = call_service(ros_node, client, Allocate.Request(scene_json=text), timeout=10.0)
        assert response.success, response.reason
        assert proc.stop() == 0, proc.output_tail()
"""

from __future__ import annotations

import ipaddress
import os
import re
import signal
import subprocess
import time
from collections.abc import Callable, Mapping
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
ENV_SCRIPT = REPO_ROOT / 'scripts' / 'env.sh'
INSTALL_DIR = REPO_ROOT / 'ros_ws' / 'install'
PROFILE_FILE = REPO_ROOT / 'config' / 'fastdds_loopback.xml'

# What scripts/env.sh sets and every ROS process must run with (ROS_DOMAIN_ID is
# checked for presence only: RAD_ROS_DOMAIN_ID may override it).
EXPECTED_DDS_ENV = {
    'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp',
    'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
    'FASTRTPS_DEFAULT_PROFILES_FILE': str(PROFILE_FILE),
    'FASTDDS_DEFAULT_PROFILES_FILE': str(PROFILE_FILE),
    'ROS_HOME': str(REPO_ROOT / '.ros'),
    'ROS_LOG_DIR': str(REPO_ROOT / '.ros' / 'log'),
}
# Variables that would point discovery somewhere else; env.sh unsets them.
FORBIDDEN_DDS_ENV = ('ROS_STATIC_PEERS', 'ROS_DISCOVERY_SERVER')


# --- the DDS environment ----------------------------------------------------------

def dds_env_problems(environ: Mapping[str, str]) -> list[str]:
    """Say what in `environ` differs from scripts/env.sh's DDS settings (empty: all fine)."""
    problems = [
        f'{key}={environ.get(key)!r}, expected {value!r}'
        for key, value in EXPECTED_DDS_ENV.items()
        if environ.get(key) != value
    ]
    if not environ.get('ROS_DOMAIN_ID', '').isdigit():
        problems.append(f"ROS_DOMAIN_ID={environ.get('ROS_DOMAIN_ID')!r}, expected a number")
    problems += [f'{key} is set' for key in FORBIDDEN_DDS_ENV if environ.get(key)]
    return problems


def load_env_script() -> dict[str, str]:
    """Return the environment scripts/env.sh produces on top of the current one."""
    out = subprocess.run(
        ['bash', '-c', f'source "{ENV_SCRIPT}" >/dev/null && env -0'],
        check=True, capture_output=True, cwd=REPO_ROOT, timeout=60,
    ).stdout
    pairs = (item.split(b'=', 1) for item in out.split(b'\0') if b'=' in item)
    return {k.decode(): v.decode() for k, v in pairs}


def read_proc_environ(pid: int) -> dict[str, str]:
    """The environment a running process was exec'd with (Linux /proc)."""
    raw = Path(f'/proc/{pid}/environ').read_bytes()
    pairs = (item.split(b'=', 1) for item in raw.split(b'\0') if b'=' in item)
    return {k.decode(errors='replace'): v.decode(errors='replace') for k, v in pairs}


# --- node processes -----------------------------------------------------------------

def executable_path(package: str, executable: str) -> Path:
    """Where `ros2 run <package> <executable>` finds an installed node."""
    path = INSTALL_DIR / package / 'lib' / package / executable
    if not os.access(path, os.X_OK):
        raise FileNotFoundError(
            f'{path} is not an installed executable; build the workspace with scripts/setup.sh '
            f'(ament_python: setup.cfg needs [install] install_scripts=$base/lib/{package})')
    return path


class NodeProcess:
    """One process started with the DDS environment, output captured to files.

    stop() ends it as Ctrl-C would (SIGINT), waits, kills it if it hangs, and
    returns the exit code: 0 for a clean Jazzy shutdown, -9 if it had to be killed.
    """

    def __init__(self, argv: list[str], log_dir: Path, name: str | None = None,
                 env: Mapping[str, str] | None = None):
        self.argv = [str(a) for a in argv]
        self.name = name or Path(self.argv[0]).name
        log_dir.mkdir(parents=True, exist_ok=True)
        self.stdout_path = log_dir / f'{self.name}.stdout'
        self.stderr_path = log_dir / f'{self.name}.stderr'
        self.killed = False
        full_env = dict(os.environ if env is None else env)
        full_env.setdefault('PYTHONUNBUFFERED', '1')  # live logs for wait_for_output
        full_env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
        with open(self.stdout_path, 'wb') as out, open(self.stderr_path, 'wb') as err:
            # A new session: a Ctrl-C on pytest must not reach the node first.
            self.popen = subprocess.Popen(
                self.argv, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                env=full_env, start_new_session=True)

    @property
    def pid(self) -> int:
        return self.popen.pid

    @property
    def returncode(self) -> int | None:
        return self.popen.poll()

    def is_running(self) -> bool:
        return self.popen.poll() is None

    def wait(self, timeout: float = 10.0) -> int:
        """Wait for the process to exit by itself; return its exit code."""
        return self.popen.wait(timeout)

    def stop(self, timeout: float = 5.0) -> int:
        """SIGINT, wait up to `timeout` s, then SIGKILL; return the exit code."""
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGINT)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.killed = True
                self.popen.kill()
                self.popen.wait()
        return self.popen.returncode

    def stdout(self) -> str:
        return self.stdout_path.read_text(errors='replace')

    def stderr(self) -> str:
        return self.stderr_path.read_text(errors='replace')

    def output_tail(self, lines: int = 30) -> str:
        """The last lines of stdout and stderr, for assertion messages."""
        def tail(text: str) -> str:
            return '\n'.join(text.splitlines()[-lines:])
        status = 'running' if self.is_running() else f'exit code {self.returncode}'
        if self.killed:
            status += ' (killed after SIGINT timed out)'
        return (f'--- {self.name} ({status}) stdout:\n{tail(self.stdout())}\n'
                f'--- {self.name} stderr:\n{tail(self.stderr())}')

    def wait_for_output(self, pattern: str, timeout: float = 10.0,
                        stream: str = 'both') -> re.Match:
        """Wait until `pattern` (a regex) appears in the process's output."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        while True:
            text = {'stdout': self.stdout, 'stderr': self.stderr}.get(
                stream, lambda: self.stdout() + self.stderr())()
            match = regex.search(text)
            if match:
                return match
            if not self.is_running():
                raise RuntimeError(f'{self.name} exited before printing {pattern!r}\n'
                                   + self.output_tail())
            if time.monotonic() > deadline:
                raise TimeoutError(f'{self.name} did not print {pattern!r} within {timeout} s\n'
                                   + self.output_tail())
            time.sleep(0.05)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def start_node(package: str, executable: str, *args: str, log_dir: Path,
               env: Mapping[str, str] | None = None) -> NodeProcess:
    """Exec an installed node exactly as `ros2 run package executable args...` would."""
    path = executable_path(package, executable)
    return NodeProcess([str(path), *args], log_dir, name=f'{package}.{executable}', env=env)


def ros_args(params: Mapping[str, object] | None = None,
             remaps: Mapping[str, str] | None = None) -> list[str]:
    """['--ros-args', '-p', 'name:=value', ..., '-r', 'from:=to', ...]."""
    args = ['--ros-args']
    for key, value in (params or {}).items():
        text = str(value).lower() if isinstance(value, bool) else str(value)
        args += ['-p', f'{key}:={text}']
    for src, dst in (remaps or {}).items():
        args += ['-r', f'{src}:={dst}']
    return args


# --- talking to nodes from the test process ------------------------------------------------

def spin_until(node, predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Spin `node` until predicate() is true; return False on timeout."""
    import rclpy

    deadline = time.monotonic() + timeout
    while not predicate():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        rclpy.spin_once(node, timeout_sec=min(0.05, remaining))
    return True


# After a client sees the server, the server may not yet see the client's reply
# reader; rmw_fastrtps then drops the first reply ("failed to send response
# (timeout): client will not receive response"), seen under load with fresh clients.
DISCOVERY_SETTLE_S = 0.5


def wait_for_plant(node, timeout: float = 30.0) -> None:
    """Wait until the plant (twin or bridge) is up: its latched /scene and a /rigid_bodies frame.

    A node started beside the plant can only know the task once the plant publishes it; a test
    that asks for a plan from motion capture must not race the plant's start-up.
    """
    from rad_msgs.msg import RigidBodies
    from rad_msgs.msg import Scene as SceneMsg
    from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data

    seen: set[str] = set()
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    subs = [node.create_subscription(SceneMsg, 'scene', lambda m: seen.add('scene'), latched),
            node.create_subscription(RigidBodies, 'rigid_bodies', lambda m: seen.add('rigid_bodies'),
                                     qos_profile_sensor_data)]
    try:
        if not spin_until(node, lambda: len(seen) == 2, timeout):
            raise TimeoutError(f'the plant published {sorted(seen) or "nothing"} of /scene and '
                               f'/rigid_bodies within {timeout} s')
    finally:
        for sub in subs:
            node.destroy_subscription(sub)
    time.sleep(DISCOVERY_SETTLE_S)


def wait_for_service(node, srv_type, name: str, timeout: float = 10.0):
    """Create a client for `name` and wait until a server is discovered (both ways); return it."""
    client = node.create_client(srv_type, name)
    if not client.wait_for_service(timeout_sec=timeout):
        node.destroy_client(client)
        raise TimeoutError(f'service {name!r} ({srv_type.__name__}) not available '
                           f'after {timeout} s (ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID")})')
    time.sleep(DISCOVERY_SETTLE_S)
    return client


def call_service(node, client, request, timeout: float = 10.0):
    """Call a service and spin `node` until the response arrives; raise TimeoutError."""
    import rclpy

    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
    if not future.done():
        client.remove_pending_request(future)
        raise TimeoutError(f'no response from {client.srv_name!r} within {timeout} s')
    return future.result()


def send_goal(node, client, goal, timeout: float = 10.0):
    """Send an action goal once its server is discovered, spin `node` until it ends; (status, result)."""
    import rclpy

    if not client.wait_for_server(timeout_sec=timeout):
        raise TimeoutError(f'action {client._action_name!r} not available after {timeout} s')
    sent = client.send_goal_async(goal)
    rclpy.spin_until_future_complete(node, sent, timeout_sec=timeout)
    if not (sent.done() and sent.result().accepted):
        raise TimeoutError(f'action {client._action_name!r} did not accept the goal within {timeout} s')
    done = sent.result().get_result_async()
    rclpy.spin_until_future_complete(node, done, timeout_sec=timeout)
    if not done.done():
        raise TimeoutError(f'action {client._action_name!r} gave no result within {timeout} s')
    return done.result().status, done.result().result


# --- what a process's sockets and the interfaces show ---------------------------------------

def udp_sockets(pid: int) -> list[tuple[str, int]]:
    """(address, port) of every UDP/IPv4 socket `pid` holds, from /proc (works across netns)."""
    inodes = set()
    for fd in Path(f'/proc/{pid}/fd').iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith('socket:['):
            inodes.add(target[len('socket:['):-1])
    sockets = []
    for line in Path(f'/proc/{pid}/net/udp').read_text().splitlines()[1:]:
        fields = line.split()
        if fields[9] in inodes:
            hex_ip, hex_port = fields[1].split(':')
            address = str(ipaddress.IPv4Address(bytes.fromhex(hex_ip)[::-1]))
            sockets.append((address, int(hex_port, 16)))
    return sorted(sockets)


def dds_receive_ports(domain_id: int) -> set[int]:
    """UDP ports Fast DDS listens on for a domain: RTPS well-known ports
    (7400 + 250 * domain + 0..249) and the 7000+ ports of per-reader locators."""
    base = 7400 + 250 * domain_id
    return set(range(7000, 7400)) | set(range(base, base + 250))


def non_loopback_receive_sockets(pid: int, domain_id: int) -> tuple[list, list]:
    """Split `pid`'s DDS receive sockets into (bound to loopback, bound elsewhere)."""
    ports = dds_receive_ports(domain_id)
    receive = [s for s in udp_sockets(pid) if s[1] in ports]
    loopback = [s for s in receive if ipaddress.IPv4Address(s[0]).is_loopback]
    return loopback, [s for s in receive if s not in loopback]


def interface_tx_packets(pid: int | str = 'self') -> dict[str, int]:
    """Transmitted packets per network interface, as the netns of `pid` sees them."""
    counters = {}
    for line in Path(f'/proc/{pid}/net/dev').read_text().splitlines()[2:]:
        name, data = line.split(':', 1)
        counters[name.strip()] = int(data.split()[9])
    return counters


def non_loopback(counters: Mapping[str, int]) -> dict[str, int]:
    return {name: value for name, value in counters.items() if name != 'lo'}


def delta(before: Mapping[str, int], after: Mapping[str, int]) -> dict[str, int]:
    return {name: after[name] - before.get(name, 0) for name in after}
