"""The visualizer: logs what the graph publishes to Rerun (see rad_core.view.viz for the entities).

Endpoints (relative names, so namespaces and remaps work):
  sub  joint_states   sensor_msgs/JointState: the Panda's links move (at most log_rate_hz)
  sub  rigid_bodies   rad_msgs/RigidBodies, sensor-data QoS: each block moves (at most log_rate_hz)
  sub  scene          rad_msgs/Scene, latched: blocks, table, target and non-target cells
  sub  plan_json      std_msgs/String, latched (depth 1): the latest plan, JSON
                      {"allocation": rad-allocation/1, "steps": [{"block", "type", "target",
                      "yaw", "cells", ...}], "timings": {stage: s}, "predicted_coverage": x}

Parameters: recording_path (.rrd, '' = none), connect_url (a Rerun gRPC proxy, '' = none),
spawn_viewer, viewer_port, application_id, log_rate_hz. Live topics go on the `ros_time`
timeline (message stamps), plan steps on the `step` sequence. The .rrd is flushed on
shutdown (Ctrl-C / SIGTERM exit 0). How to watch: see the package README.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import time
from urllib.parse import urlparse

import rerun as rr
from rad_core.domain.errors import RadError
from rad_core.view import viz
from rad_msgs.msg import RigidBodies
from rad_msgs.msg import Scene as SceneMsg
from rad_ros.conversions import scene_from_msg
from rad_ros.node_main import main_for
from rad_ros.params import Param, declare
from rad_ros.qos import LATCHED
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_msgs.msg import String


def server_problem(url: str, timeout: float = 1.0) -> str:
    """'' when something listens at a rerun+http://host:port/proxy URL, else why not."""
    parsed = urlparse(url.replace('rerun+http', 'http', 1))
    if parsed.scheme not in ('http', 'https') or not parsed.hostname:
        return 'not a rerun+http://host:port/proxy URL'
    try:
        with socket.create_connection((parsed.hostname, parsed.port or 9876), timeout=timeout):
            return ''
    except OSError as e:
        return f'nothing listens there ({e.strerror or e})'


def stamp_s(header, fallback: float) -> float:
    t = header.stamp.sec + header.stamp.nanosec * 1e-9
    return t if t > 0 else fallback


# All read when the node starts: read-only.
PARAMS = [Param('recording_path', 'recording.rrd', "the .rrd file the graph is saved to ('' = none)"),
          Param('connect_url', '', "a running Rerun viewer's URL to stream to ('' = none)"),
          Param('spawn_viewer', False, 'start a Rerun viewer and stream to it'),
          Param('viewer_port', 9876, "the spawned viewer's port", range=(1024, 65535)),
          Param('application_id', 'rad', "Rerun's application id"),
          Param('log_rate_hz', 20.0, 'how often joint states and bodies are logged, at most', range=(0.1, 1000.0)),
          Param('effector', 'hand', "the robot's effector drawn: hand or suction")]

class VizNode(Node):
    def __init__(self):
        super().__init__('viz')
        declare(self, PARAMS)
        rate = float(self.get_parameter('log_rate_hz').value)
        if not rate > 0:
            raise RadError(f'log_rate_hz must be positive, got {rate}')

        self.rec = rr.RecordingStream(self.get_parameter('application_id').value)
        self.rec.set_log_tick_enabled(False)    # two timelines only: ros_time and step
        self.rec.set_log_time_enabled(False)
        self.sinks = self._sinks()
        if self.sinks:
            self.rec.set_sinks(*self.sinks, default_blueprint=viz.default_blueprint())
        else:
            self.get_logger().warning('recording_path, connect_url and spawn_viewer are all off: logging nothing')

        self.robot = viz.PandaModel(effector=str(self.get_parameter('effector').value))
        self.scene = None
        self.known_blocks: set[str] = set()
        self.plan = None
        self.plan_logged = None
        self.joints: JointState | None = None
        self.bodies: RigidBodies | None = None
        self.counts = {'joint_states': 0, 'rigid_bodies': 0, 'scenes': 0, 'plans': 0}
        self.started = time.monotonic()
        if self.sinks:
            viz.log_world(self.rec)
            self.robot.log_model(self.rec)

        self.create_subscription(JointState, 'joint_states', self.joint_states_callback, 10)
        self.create_subscription(RigidBodies, 'rigid_bodies', self.rigid_bodies_callback, qos_profile_sensor_data)
        self.create_subscription(SceneMsg, 'scene', self.scene_callback, LATCHED)
        self.create_subscription(String, 'plan_json', self.plan_callback, LATCHED)
        self.create_timer(1.0 / rate, self.log_callback)
        self.get_logger().info('viz ready: ' + (', '.join(str(s) for s in self.sink_names) or 'no sink'))

    def _sinks(self) -> list:
        sinks, self.sink_names = [], []
        path = self.get_parameter('recording_path').value
        if path:
            sinks.append(rr.FileSink(path))
            self.sink_names.append(f'recording {path}')
        url = self.get_parameter('connect_url').value
        if self.get_parameter('spawn_viewer').value and not url:
            url = self._spawn_viewer(int(self.get_parameter('viewer_port').value))
        if url:
            problem = server_problem(url)
            if problem:
                # A GrpcSink to nobody stalls set_sinks 5 s and fails every flush: record to file only.
                self.get_logger().error(f'connect_url {url}: {problem}; not streaming live '
                                        '(start `rerun --serve-web --bind 127.0.0.1` first)')
            else:
                sinks.append(rr.GrpcSink(url))
                self.sink_names.append(f'live {url}')
        return sinks

    def _spawn_viewer(self, port: int) -> str:
        """A native viewer whose gRPC server listens on loopback only (rr.spawn cannot bind it)."""
        exe = shutil.which('rerun')
        if exe is None:
            self.get_logger().error('spawn_viewer: no rerun executable on PATH')
            return ''
        self.viewer = subprocess.Popen([exe, '--bind', '127.0.0.1', '--port', str(port)],
                                       stdin=subprocess.DEVNULL, start_new_session=True)
        url = f'rerun+http://127.0.0.1:{port}/proxy'
        deadline = time.monotonic() + 10.0
        while server_problem(url, timeout=0.2) and time.monotonic() < deadline:
            if self.viewer.poll() is not None:
                self.get_logger().error(f'spawn_viewer: the viewer exited with code {self.viewer.returncode} '
                                        '(no display?)')
                return ''
            time.sleep(0.2)
        return url

    # ---- callbacks: keep the latest, log at log_rate_hz ----------------------------------
    def joint_states_callback(self, msg: JointState) -> None:
        self.joints = msg

    def rigid_bodies_callback(self, msg: RigidBodies) -> None:
        self.bodies = msg

    def log_callback(self) -> None:
        if not self.sinks:
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.joints is not None:
            msg, self.joints = self.joints, None
            viz.set_ros_time(self.rec, stamp_s(msg.header, now))
            self.robot.log_joints(self.rec, list(msg.name), list(msg.position))
            self.counts['joint_states'] += 1
        if self.bodies is not None and self.scene is not None:
            msg, self.bodies = self.bodies, None
            viz.set_ros_time(self.rec, stamp_s(msg.header, now))
            poses = [(b.rigid_body_name,
                      (b.pose.position.x, b.pose.position.y, b.pose.position.z),
                      (b.pose.orientation.x, b.pose.orientation.y, b.pose.orientation.z, b.pose.orientation.w))
                     for b in msg.rigidbodies if b.tracking_valid]
            viz.log_block_poses(self.rec, poses, self.known_blocks)
            self.counts['rigid_bodies'] += 1

    def scene_callback(self, msg: SceneMsg) -> None:
        try:
            scene = scene_from_msg(msg)
        except RadError as e:
            self.get_logger().error(f'scene not shown: {e}')
            return
        previous, self.scene, self.known_blocks = self.scene, scene, {b.id for b in scene.blocks}
        self.counts['scenes'] += 1
        if self.sinks:
            viz.set_ros_time(self.rec, stamp_s(msg.header, self.get_clock().now().nanoseconds * 1e-9))
            viz.log_scene(self.rec, scene, previous)
            if previous is None:
                self.get_logger().info(f'scene logged: {len(scene.blocks)} blocks, {len(scene.targets)} regions')
        self._log_plan()

    def plan_callback(self, msg: String) -> None:
        try:
            self.plan = viz.parse_plan(msg.data)
        except RadError as e:
            self.get_logger().error(f'plan_json not shown: {e}')
            return
        self.counts['plans'] += 1
        self._log_plan()

    def _log_plan(self) -> None:
        if not self.sinks or self.plan is None:
            return
        if self.scene is None:
            self.get_logger().info('plan received; drawn once a scene arrives')
            return
        problems = viz.log_plan(self.rec, self.scene, self.plan, self.get_clock().now().nanoseconds * 1e-9,
                                previous=self.plan_logged)
        if self.plan_logged is None:
            self.get_logger().info('plan logged')
        self.plan_logged = self.plan
        for p in problems:
            self.get_logger().warning(f'plan: {p}')

    def destroy_node(self):
        elapsed = time.monotonic() - self.started
        rates = ', '.join(f'{k} {v}' for k, v in self.counts.items())
        if self.sinks:
            try:
                self.rec.flush(timeout_sec=10.0)
            except RuntimeError as e:    # a live viewer that went away; the file sink is flushed regardless
                print(f'[viz] flush: {e}', flush=True)
            self.rec.disconnect()
        summary = f'viz logged in {elapsed:.1f} s: {rates}'
        if self.context.ok():
            self.get_logger().info(summary)
        else:   # after Ctrl-C the context is gone and /rosout with it
            print(f'[viz] {summary}', flush=True)
        return super().destroy_node()


main = main_for(VizNode)
