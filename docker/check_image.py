"""The rad image's own test, the last step of its build (docker/Dockerfile): every import rad needs
works and every Python package is at the version scripts/setup.sh installs. Prints one line per
check with the versions, and exits non-zero (failing the build) on any error.

    . /opt/ros/jazzy/setup.sh && . ros_ws/install/setup.sh && python3 docker/check_image.py

Stdlib only besides what it checks. Starts no DDS participant (no rclpy.init): message round trips
go through the C type support with rclpy.serialization, which is where numpy's ABI matters.
"""

from __future__ import annotations

import importlib
import importlib.metadata as metadata
import re
import sys
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
failures: list[str] = []
APT = '/opt/ros/jazzy'   # where the apt ROS packages are


def check(name: str):
    """Run the decorated function at once; print 'ok name: result' or 'FAIL name: error'."""
    def run(function):
        try:
            print(f'ok    {name}: {function()}')
        except Exception as error:  # noqa: BLE001 - every failure is reported, then the build fails
            traceback.print_exc()
            print(f'FAIL  {name}: {type(error).__name__}: {error}')
            failures.append(name)
        return function
    return run


def norm(name: str) -> str:
    return re.sub(r'[-_.]+', '-', name).lower()


def pins(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if '==' in line:
            name, version = line.split('==', 1)
            out[norm(name)] = version.strip()
    return out


@check('python')
def _python():
    assert sys.version_info[:2] == (3, 12), sys.version
    return sys.version.split()[0]


@check('numpy (pip, constraints.txt)')
def _numpy():
    import numpy
    want = pins(ROOT / 'requirements' / 'constraints.txt')['numpy']
    assert numpy.__version__ == want, f'numpy {numpy.__version__} from {numpy.__file__}, constraints.txt: {want}'
    assert '/usr/local/' in numpy.__file__, f'numpy is not the pip one: {numpy.__file__}'
    return f'{numpy.__version__} ({numpy.__file__})'


@check('python packages = requirements/constraints.txt')
def _resolve():
    constraints = pins(ROOT / 'requirements' / 'constraints.txt')
    wanted = set()
    for line in (ROOT / 'requirements' / 'requirements.txt').read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if line and not re.match(r'(ros-|colcon-)', line):
            wanted.add(norm(re.split(r'[=<>!~\[; ]', line, maxsplit=1)[0]))
    wrong = []
    for name in sorted(wanted):
        have = metadata.version(name)
        if constraints.get(name) != have:
            wrong.append(f'{name} {have} (constraints.txt: {constraints.get(name)})')
    assert not wrong, '; '.join(wrong)
    # Distributions pip put in /usr/local that constraints.txt does not pin (it is `pip freeze` of a
    # Python 3.11 venv, which leaves out setuptools): reported, not failed.
    loose = sorted(f'{d.metadata["Name"]} {d.version}' for d in metadata.distributions()
                   if '/usr/local/' in str(d.locate_file('')) and norm(d.metadata['Name']) not in constraints)
    return f'{len(wanted)} direct requirements at their pins' + (f'; not in constraints.txt: {", ".join(loose)}'
                                                               if loose else '')


MODULES = (('torch', 'torch'), ('ortools', 'ortools'), ('pybullet', 'pybullet'), ('rerun', 'rerun-sdk'),
           ('scipy', 'scipy'), ('ruckig', 'ruckig'), ('trimesh', 'trimesh'), ('mcap_ros2', 'mcap-ros2-support'))
for module, label in MODULES:
    @check(f'import {module}')
    def _import(module=module, label=label):
        importlib.import_module(module)
        return metadata.version(label)


@check('torch computes (CPU build)')
def _torch():
    import torch
    x = torch.ones(3, dtype=torch.float64) @ torch.arange(3, dtype=torch.float64)
    assert float(x) == 3.0
    assert torch.from_numpy(__import__('numpy').arange(3.0)).sum().item() == 3.0
    return torch.__version__


@check('ortools CP-SAT solves')
def _ortools():
    from ortools.sat.python import cp_model
    model = cp_model.CpModel()
    x = model.new_int_var(0, 3, 'x')
    model.maximize(x)
    solver = cp_model.CpSolver()
    assert solver.solve(model) == cp_model.OPTIMAL and solver.value(x) == 3
    return 'optimal'


@check('pybullet steps (DIRECT)')
def _pybullet():
    import pybullet
    client = pybullet.connect(pybullet.DIRECT)
    pybullet.stepSimulation(physicsClientId=client)
    pybullet.disconnect(client)
    return 'ok'


@check('import rclpy')
def _rclpy():
    import rclpy
    from rclpy.serialization import deserialize_message, serialize_message  # noqa: F401
    return rclpy.__file__


def metadata_of(package: str, prefix: str = '') -> str:
    """The package.xml version and install prefix of an ament package (which must be `prefix`)."""
    from ament_index_python.packages import get_package_prefix, get_package_share_directory
    xml = (Path(get_package_share_directory(package)) / 'package.xml').read_text()
    version = re.search(r'<version>\s*([^<\s]+)', xml).group(1)
    where = get_package_prefix(package)
    assert not prefix or where == prefix, f'{package} is from {where}, not {prefix}'
    return f'{version} ({where})'


def roundtrip(message):
    from rclpy.serialization import deserialize_message, serialize_message
    back = deserialize_message(serialize_message(message), type(message))
    assert back == message, f'{type(message).__name__} changed in a round trip'
    return back


@check('sensor_msgs (apt, numpy fixed arrays)')
def _sensor_msgs():
    import numpy
    from sensor_msgs.msg import Imu
    message = Imu()
    message.orientation_covariance = numpy.arange(9.0)
    back = roundtrip(message)
    assert isinstance(back.orientation_covariance, numpy.ndarray)
    assert back.orientation_covariance.tolist() == list(range(9))
    return 'Imu.orientation_covariance float64[9] as numpy.ndarray'


@check('control_msgs (apt)')
def _control_msgs():
    import numpy
    from control_msgs.action import FollowJointTrajectory, GripperCommand
    from trajectory_msgs.msg import JointTrajectoryPoint
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = [f'fr3_joint{i}' for i in range(1, 8)]
    goal.trajectory.points = [JointTrajectoryPoint(positions=numpy.linspace(0.0, 0.6, 7).tolist())]
    roundtrip(goal)
    roundtrip(GripperCommand.Goal())
    return metadata_of('control_msgs', APT)


@check('tf2_msgs (apt)')
def _tf2_msgs():
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    roundtrip(TFMessage(transforms=[TransformStamped(child_frame_id='b1')]))
    return metadata_of('tf2_msgs', APT)


@check('mocap4r2_msgs (apt)')
def _mocap4r2_msgs():
    from mocap4r2_msgs.msg import RigidBodies, RigidBody
    roundtrip(RigidBodies(rigidbodies=[RigidBody(rigid_body_name='b1')]))
    return metadata_of('mocap4r2_msgs', APT)


@check('rad_msgs (workspace) and rad_ros conversions')
def _rad_msgs():
    import numpy
    from rad_msgs.msg import PlanStep
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    step = PlanStep(trajectories=[JointTrajectory(points=[JointTrajectoryPoint(
        positions=numpy.zeros(7).tolist(), velocities=numpy.ones(7).tolist())])])
    roundtrip(step)
    importlib.import_module('rad_ros')
    return metadata_of('rad_msgs')


@check('rad nodes import')
def _rad_nodes():
    for module in ('rad_core', 'rad_planner.assembly_node', 'rad_planner.allocation_node', 'rad_planner.sequencer_node',
                   'rad_gamp.gamp_node', 'rad_sim.twin_node', 'rad_viz.viz_node', 'rad_viz.markers_node'):
        importlib.import_module(module)
    return 'ok'


if failures:
    print(f'check_image: {len(failures)} failed: {", ".join(failures)}')
    sys.exit(1)
print('check_image: all passed')
