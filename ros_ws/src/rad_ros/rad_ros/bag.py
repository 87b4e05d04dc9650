"""Recording and replaying a rad run as an MCAP file that `ros2 bag` and Foxglove read.

`BAG_TOPICS` is the documented topic set of a run: what the twin, the assembly node and the
markers node publish, each with its type and QoS (latched = transient_local, the latest message
kept for late subscribers). `Recorder` subscribes to them with serialized (raw) subscriptions and
writes every message's CDR bytes unchanged; `play` publishes them again with the QoS they were
offered with and the recorded timing.

The file is laid out as rosbag2's MCAP storage plugin writes it, so that `ros2 bag info`,
`ros2 bag play` and Foxglove read it:
  * profile `ros2`; one Schema per message type, named `pkg/msg/Type`, encoding `ros2msg`, its data
    the full message definition: the type's .msg text, then each nested type (depth first, sorted,
    each once) as a section opened by a line of 80 '=' and `MSG: pkg/Type`;
  * one Channel per topic (the resolved name), message encoding `cdr`, metadata
    `offered_qos_profiles` (a YAML list of the publishers' QoS, in rosbag2's metadata version 9
    form: policy names as strings, durations as sec/nsec) and `topic_type_hash` (empty);
  * Messages with log_time = when the recorder received it (the recorder node's clock, ns) and
    publish_time = the publisher's source timestamp;
  * a Metadata record `rosbag2` whose `serialized_metadata` is the bag metadata (version 9), which
    tells rosbag2 how to read the QoS strings; chunked, zstd-compressed, with a summary
    (statistics, indexes).
"""

from __future__ import annotations

import dataclasses
import importlib
import re
import struct
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import CompressionType, Writer
from rad_core.domain.errors import RadError

BAG_METADATA_VERSION = 9           # rosbag2 (Jazzy): QoS policies as strings in offered_qos_profiles
ROS_DISTRO = 'jazzy'
DELIMITER = '=' * 80
PRIMITIVE_TYPES = frozenset({'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
                             'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'})
# A field's type at the start of a line of a .msg ("pkg/Type[] name", "Type name", "float64[3] x").
_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
CLOCK_TOPIC = '/clock'


class BagError(RadError):
    """A bag that cannot be written or read (a missing file, an unknown type, a foreign layout)."""


@dataclasses.dataclass(frozen=True)
class BagTopic:
    """One topic of a rad run: `name` as the nodes publish it in the root namespace (a relative name
    resolves in the recorder's namespace), its `type` ('pkg/msg/Type'), whether it is `latched`
    (transient_local: only the latest message, kept for late subscribers) and whether its
    publisher is `best_effort` (sensor-data QoS)."""
    name: str
    type: str
    publisher: str
    description: str
    latched: bool = False
    best_effort: bool = False

    def subscription_qos(self):
        """The QoS that matches the publisher and loses nothing a subscriber can get: transient_local
        for a latched topic (its message is caught even when published before the recorder started),
        best effort for a best-effort publisher (a reliable subscription would not match it)."""
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=100,
            reliability=ReliabilityPolicy.BEST_EFFORT if self.best_effort else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if self.latched else DurabilityPolicy.VOLATILE)

    def offered_qos(self):
        """The QoS rad's publisher offers on this topic (rad_ros.qos.LATCHED, sensor data, or depth 10)."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        return QoSProfile(
            depth=1 if self.latched else (5 if self.best_effort else 10),
            reliability=ReliabilityPolicy.BEST_EFFORT if self.best_effort else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if self.latched else DurabilityPolicy.VOLATILE)


BAG_TOPICS: tuple[BagTopic, ...] = (
    BagTopic('scene', 'rad_msgs/msg/Scene', 'twin', 'the scene last loaded', latched=True),
    BagTopic('robot_description', 'std_msgs/msg/String', 'twin', 'the URDF simulated, for RViz', latched=True),
    BagTopic('plan_json', 'std_msgs/msg/String', 'assembly_node', 'the latest plan, as JSON', latched=True),
    BagTopic('/tf_static', 'tf2_msgs/msg/TFMessage', 'twin, assembly_node',
             'the robot under the base frame (the twin\'s), and the motion-capture frame once calibrated',
             latched=True),
    BagTopic('markers', 'visualization_msgs/msg/MarkerArray', 'markers_node',
             'target cells, blocks, allocation and next step for RViz', latched=True),
    BagTopic('joint_states', 'sensor_msgs/msg/JointState', 'twin', 'the arm and finger joints'),
    BagTopic('rigid_bodies', 'rad_msgs/msg/RigidBodies', 'twin', 'motion capture: every block, frame number',
             best_effort=True),
    BagTopic('/tf', 'tf2_msgs/msg/TFMessage', 'twin', 'each block\'s true pose, 10 Hz'),
    BagTopic('twin/events', 'std_msgs/msg/String', 'twin', 'accepted / rejected / done / fault events, JSON'),
    BagTopic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', 'assembly_node', 'health checks, 1 Hz'),
    BagTopic(CLOCK_TOPIC, 'rosgraph_msgs/msg/Clock', 'twin', 'simulated time, when publish_clock is true'),
)
"""The documented topic set of a rad run (docs/ros.md, "Recording and replaying a run")."""


def bag_topic(name: str) -> BagTopic | None:
    """The BAG_TOPICS entry for `name` (relative or with a leading '/'), None if it is not one."""
    bare = name.lstrip('/')
    return next((t for t in BAG_TOPICS if t.name.lstrip('/') == bare), None)


# --- message definitions ----------------------------------------------------------------------------

def _split_type(type_name: str) -> tuple[str, str, str]:
    """'pkg/msg/Type' or 'pkg/Type' -> (pkg, 'msg', Type)."""
    parts = type_name.split('/')
    if len(parts) == 2:
        return parts[0], 'msg', parts[1]
    if len(parts) == 3 and all(parts):
        return parts[0], parts[1], parts[2]
    raise BagError(f'message type {type_name!r} is not of the form pkg/msg/Type')


def _msg_text(type_name: str) -> str:
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    package, namespace, name = _split_type(type_name)
    try:
        share = Path(get_package_share_directory(package))
    except PackageNotFoundError:
        raise BagError(f'no package {package!r} in the ament index (for {type_name}); '
                       'is the workspace sourced (scripts/env.sh)?') from None
    path = share / namespace / f'{name}.msg'
    if not path.is_file():
        raise BagError(f'no message definition {path} for {type_name}')
    return path.read_text()


def _dependencies(text: str, package: str) -> list[str]:
    """The message types `text` (a .msg) uses, as 'pkg/Type', sorted, each once."""
    found = set()
    for match in _FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in PRIMITIVE_TYPES:
            continue
        found.add(field_type if '/' in field_type else f'{package}/{field_type}')
    return sorted(found)


def message_definition(type_name: str) -> str:
    """The full `ros2msg` definition of `type_name` ('pkg/msg/Type') as rosbag2 stores it: the type's
    .msg text, then each nested type once, depth first in sorted order, each after a line of 80 '='
    and 'MSG: pkg/Type'. Read from the installed .msg files (ament index)."""
    seen: set[str] = set()

    def expand(name: str, depth: int) -> str:
        if depth > 50:
            raise BagError(f'message definition of {type_name} nests deeper than 50 types')
        text = _msg_text(name)
        result = text
        for dep in _dependencies(text, _split_type(name)[0]):
            if dep not in seen:
                seen.add(dep)
                result += f'\n{DELIMITER}\nMSG: {dep}\n' + expand(dep, depth + 1)
        return result

    return expand(type_name, 0)


def message_class(type_name: str):
    """The Python message class of 'pkg/msg/Type'."""
    package, namespace, name = _split_type(type_name)
    try:
        return getattr(importlib.import_module(f'{package}.{namespace}'), name)
    except (ImportError, AttributeError):
        raise BagError(f'message type {type_name} is not installed (no {package}.{namespace}.{name})') from None


# --- QoS as rosbag2 writes it ---------------------------------------------------------------------

_INFINITE_NS = 9223372036854775807


def _duration(value) -> dict:
    ns = getattr(value, 'nanoseconds', value)
    ns = min(int(ns), _INFINITE_NS)
    return {'sec': ns // 1_000_000_000, 'nsec': ns % 1_000_000_000}


def qos_to_dict(qos) -> dict:
    """One rclpy QoSProfile as an entry of rosbag2's `offered_qos_profiles` (version 9)."""
    return {
        'history': qos.history.name.lower(),
        'depth': int(qos.depth),
        'reliability': qos.reliability.name.lower(),
        'durability': qos.durability.name.lower(),
        'deadline': _duration(qos.deadline),
        'lifespan': _duration(qos.lifespan),
        'liveliness': qos.liveliness.name.lower(),
        'liveliness_lease_duration': _duration(qos.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions),
    }


def qos_profiles_yaml(profiles: Iterable) -> str:
    """The `offered_qos_profiles` string of a channel: a YAML list, one entry per publisher."""
    return yaml.safe_dump([qos_to_dict(q) for q in profiles], sort_keys=False)


def _policy(enum, value, topic: str):
    """A policy from rosbag2's YAML: a name (version 9) or the rmw enum's number (version 8 and older)."""
    try:
        return enum(value) if isinstance(value, int) else enum[str(value).upper()]
    except (KeyError, ValueError):
        raise BagError(f'{topic}: offered_qos_profiles has {enum.__name__} {value!r}, not one rclpy knows') from None


def replay_qos(offered: str, topic: str, fallback=None):
    """The QoS to publish `topic` with on replay, from its channel's `offered_qos_profiles`: the first
    publisher's reliability, durability and depth (a latched topic stays latched). Deadline, lifespan and
    liveliness are left at their defaults, which every subscriber accepts. With no profile recorded:
    `fallback`, else reliable, volatile, depth 10."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    profiles = yaml.safe_load(offered) if offered and offered.strip() else None
    if not profiles:
        return fallback if fallback is not None else QoSProfile(depth=10)
    if not isinstance(profiles, list) or not isinstance(profiles[0], dict):
        raise BagError(f'{topic}: offered_qos_profiles is not a YAML list of profiles: {offered[:80]!r}')
    first = profiles[0]
    reliability = _policy(ReliabilityPolicy, first.get('reliability', 'reliable'), topic)
    durability = _policy(DurabilityPolicy, first.get('durability', 'volatile'), topic)
    history = _policy(HistoryPolicy, first.get('history', 'keep_last'), topic)
    if reliability not in (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT):
        reliability = ReliabilityPolicy.RELIABLE
    if durability not in (DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL):
        durability = DurabilityPolicy.VOLATILE
    if history == HistoryPolicy.KEEP_ALL:
        return QoSProfile(history=history, reliability=reliability, durability=durability)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, int(first.get('depth') or 1)),
                      reliability=reliability, durability=durability)


# --- writing ------------------------------------------------------------------------------------------

@dataclasses.dataclass
class _Channel:
    id: int
    type: str
    offered_qos: str
    count: int = 0


class BagWriter:
    """An MCAP file in rosbag2's layout (see the module docstring); `close()` writes the summary and the
    rosbag2 metadata. Not thread-safe: one thread writes."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if self.path.suffix != '.mcap':
            raise BagError(f'{self.path}: a bag file must end in .mcap')
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.path, 'wb')
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile=Profile.ROS2, library='rad_ros.bag (mcap python)')
        self._schemas: dict[str, int] = {}
        self.channels: dict[str, _Channel] = {}
        self.first_ns: int | None = None
        self.last_ns: int | None = None
        self.closed = False

    def add_topic(self, topic: str, type_name: str, offered_qos: str) -> None:
        """Register `topic` (its schema once per type); a topic already there is left as it is."""
        if topic in self.channels:
            return
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                type_name, SchemaEncoding.ROS2, message_definition(type_name).encode())
        channel_id = self._writer.register_channel(
            topic, MessageEncoding.CDR, self._schemas[type_name],
            {'offered_qos_profiles': offered_qos, 'topic_type_hash': ''})
        self.channels[topic] = _Channel(channel_id, type_name, offered_qos)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """One serialized (CDR) message of a registered topic."""
        channel = self.channels[topic]
        self._writer.add_message(channel.id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns if publish_time_ns else log_time_ns,
                                 sequence=channel.count % (1 << 32))
        channel.count += 1
        self.first_ns = log_time_ns if self.first_ns is None else min(self.first_ns, log_time_ns)
        self.last_ns = log_time_ns if self.last_ns is None else max(self.last_ns, log_time_ns)

    def _bag_metadata(self) -> str:
        start = self.first_ns or 0
        duration = (self.last_ns or 0) - start
        total = sum(c.count for c in self.channels.values())
        topics = [{'topic_metadata': {'name': name, 'type': c.type, 'serialization_format': 'cdr',
                                      'offered_qos_profiles': c.offered_qos, 'type_description_hash': ''},
                   'message_count': c.count} for name, c in self.channels.items()]
        metadata = {
            'version': BAG_METADATA_VERSION, 'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration}, 'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': total, 'topics_with_message_count': topics,
            'compression_format': '', 'compression_mode': '',
            'relative_file_paths': [self.path.name],
            'files': [{'path': self.path.name, 'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration}, 'message_count': total}],
            'custom_data': {}, 'ros_distro': ROS_DISTRO,
        }
        return yaml.safe_dump(metadata, sort_keys=False)

    def close(self) -> None:
        """Write the rosbag2 metadata and the summary, and close the file (once)."""
        if self.closed:
            return
        self.closed = True
        self._writer.add_metadata('rosbag2', {'serialized_metadata': self._bag_metadata()})
        self._writer.finish()
        self._stream.close()


# --- recording ------------------------------------------------------------------------------------------

class Recorder:
    """Records `topics` (BAG_TOPICS names, or any topic whose type the graph advertises) from `node` into
    a BagWriter at `path`. Each topic of BAG_TOPICS is subscribed at once, with BagTopic.subscription_qos;
    any other is subscribed once a publisher advertises its type, with QoS adapted to the publishers' offers
    as `ros2 bag record` does (reliable / transient_local only when every publisher offers it). A topic's
    channel is written with its first message, its offered_qos_profiles taken from the publishers then
    seen (BagTopic.offered_qos when none is)."""

    def __init__(self, node, path: str | Path, topics: Iterable[str] | None = None):
        self.node = node
        self.writer = BagWriter(path)
        self.lock = threading.Lock()
        names = list(topics) if topics is not None else [t.name for t in BAG_TOPICS]
        if not names:
            raise BagError('no topics to record')
        self.pending: dict[str, BagTopic | None] = {}
        for name in names:
            resolved = node.resolve_topic_name(name)
            self.pending.setdefault(resolved, bag_topic(name))
        self.subscriptions = {}
        self.types: dict[str, str] = {}
        self._subscribe_known()
        self.timer = node.create_timer(0.5, self._subscribe_discovered) if self.pending else None

    def _subscribe(self, topic: str, type_name: str, qos) -> None:
        msg_class = message_class(type_name)
        message_definition(type_name)          # fails now, naming the type, rather than at the first message
        self.types[topic] = type_name
        self.subscriptions[topic] = self.node.create_subscription(
            msg_class, topic, lambda data, info, t=topic: self._received(t, data, info), qos, raw=True)
        del self.pending[topic]

    def _subscribe_known(self) -> None:
        for topic, known in list(self.pending.items()):
            if known is not None:
                self._subscribe(topic, known.type, known.subscription_qos())

    def _subscribe_discovered(self) -> None:
        advertised = dict(self.node.get_topic_names_and_types())
        for topic in list(self.pending):
            types = advertised.get(topic)
            if not types:
                continue
            if len(types) > 1:
                self.node.get_logger().warning(f'{topic} is advertised with types {types}; recording {types[0]}')
            self._subscribe(topic, types[0], self._adapted_qos(topic))
            self.node.get_logger().info(f'recording {topic} ({types[0]})')
        if not self.pending and self.timer is not None:
            self.timer.cancel()

    def _adapted_qos(self, topic: str):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        offers = [info.qos_profile for info in self.node.get_publishers_info_by_topic(topic)]
        reliable = bool(offers) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in offers)
        latched = bool(offers) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offers)
        return QoSProfile(depth=100,
                          reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)

    def _offered_qos(self, topic: str) -> str:
        offers = [info.qos_profile for info in self.node.get_publishers_info_by_topic(topic)]
        if not offers:
            known = bag_topic(topic)
            offers = [known.offered_qos()] if known is not None else []
        return qos_profiles_yaml(offers)

    def _received(self, topic: str, data: bytes, info) -> None:
        log_time = self.node.get_clock().now().nanoseconds
        publish_time = info.get('source_timestamp') if isinstance(info, dict) else None
        with self.lock:
            if self.writer.closed:
                return
            if topic not in self.writer.channels:
                self.writer.add_topic(topic, self.types[topic], self._offered_qos(topic))
                self.node.get_logger().info(f'first message on {topic}')
            self.writer.write(topic, bytes(data), log_time, publish_time)

    def counts(self) -> dict[str, int]:
        """Messages recorded so far, per topic."""
        with self.lock:
            return {topic: c.count for topic, c in self.writer.channels.items()}

    def close(self) -> None:
        """Stop recording and finish the file (a valid MCAP with its summary)."""
        with self.lock:
            for sub in self.subscriptions.values():
                self.node.destroy_subscription(sub)
            self.subscriptions.clear()
            if self.timer is not None:
                self.node.destroy_timer(self.timer)
                self.timer = None
            self.writer.close()


# --- reading -----------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: its resolved name, type, message count and recorded offered_qos_profiles."""
    name: str
    type: str
    count: int
    offered_qos: str

    @property
    def latched(self) -> bool:
        """Whether its (first) publisher offered transient_local durability."""
        profiles = yaml.safe_load(self.offered_qos) if self.offered_qos.strip() else None
        return bool(profiles) and str(profiles[0].get('durability')) in ('transient_local', '1')


@dataclasses.dataclass(frozen=True)
class BagInfo:
    """What `bag info` prints: the topics and the time span (log times, ns) of a bag file."""
    path: Path
    topics: tuple[TopicInfo, ...]
    start_ns: int
    end_ns: int
    size_bytes: int

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9

    def format(self) -> str:
        """A `ros2 bag info`-like text."""
        lines = [f'File:        {self.path}',
                 f'Size:        {self.size_bytes / 1024:.1f} KiB',
                 f'Duration:    {self.duration_s:.3f} s',
                 f'Start:       {self.start_ns / 1e9:.3f}',
                 f'End:         {self.end_ns / 1e9:.3f}',
                 f'Messages:    {self.message_count}',
                 'Topics:']
        width = max((len(t.name) for t in self.topics), default=0)
        for t in self.topics:
            lines.append(f'  {t.name:<{width}}  {t.type}  count {t.count}' + ('  latched' if t.latched else ''))
        return '\n'.join(lines)


def _open(path: str | Path):
    path = Path(path)
    if not path.is_file():
        raise BagError(f'{path}: no such bag file')
    return path, open(path, 'rb')


def info(path: str | Path) -> BagInfo:
    """Topics, types, message counts and time span of the bag at `path`, from its summary (the whole
    file is scanned when it has none, as after a crash)."""
    path, stream = _open(path)
    with stream:
        try:
            summary = make_reader(stream).get_summary()
        except (McapError, EOFError, ValueError, struct.error) as e:
            raise BagError(f'{path}: not a readable MCAP file ({e})') from None
        if summary is None or summary.statistics is None:
            return _scan_info(path)
        counts = summary.statistics.channel_message_counts
        topics = tuple(TopicInfo(c.topic, summary.schemas[c.schema_id].name if c.schema_id in summary.schemas
                                 else '', counts.get(cid, 0), c.metadata.get('offered_qos_profiles', ''))
                       for cid, c in sorted(summary.channels.items()))
        return BagInfo(path, topics, summary.statistics.message_start_time, summary.statistics.message_end_time,
                       path.stat().st_size)


def _scan_info(path: Path) -> BagInfo:
    counts: dict[int, int] = {}
    channels = {}
    schemas = {}
    start, end = None, None
    with open(path, 'rb') as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            channels[channel.id] = channel
            schemas[channel.id] = schema.name if schema else ''
            counts[channel.id] = counts.get(channel.id, 0) + 1
            start = message.log_time if start is None else min(start, message.log_time)
            end = message.log_time if end is None else max(end, message.log_time)
    topics = tuple(TopicInfo(c.topic, schemas[cid], counts[cid], c.metadata.get('offered_qos_profiles', ''))
                   for cid, c in sorted(channels.items()))
    return BagInfo(path, topics, start or 0, end or 0, path.stat().st_size)


@dataclasses.dataclass(frozen=True)
class BagMessage:
    """One recorded message: its CDR bytes as received, with its topic's type and offered QoS."""
    topic: str
    type: str
    data: bytes
    log_time_ns: int
    offered_qos: str


def messages(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """The bag's messages in log-time order, optionally only those of `topics` (resolved names)."""
    path, stream = _open(path)
    wanted = set(topics) if topics is not None else None
    with stream:
        reader = make_reader(stream)
        for schema, channel, message in reader.iter_messages(
                topics=list(wanted) if wanted is not None else None, log_time_order=True):
            if channel.message_encoding != MessageEncoding.CDR:
                raise BagError(f'{path}: topic {channel.topic} is encoded {channel.message_encoding!r}, '
                               'not cdr (not a ROS 2 bag)')
            yield BagMessage(channel.topic, schema.name if schema else '', message.data, message.log_time,
                             channel.metadata.get('offered_qos_profiles', ''))


# --- playing ------------------------------------------------------------------------------------------------

@dataclasses.dataclass
class PlayOptions:
    """How `play` replays: speed, /clock, a start delay for discovery, a topic filter (resolved names)."""
    rate: float = 1.0                  # 2.0: twice as fast
    clock_hz: float = 0.0              # > 0: publish /clock from the recorded time at this rate (--clock)
    delay_s: float = 0.0               # wait this long after creating the publishers (discovery)
    topics: tuple[str, ...] | None = None


def play(node, path: str | Path, options: PlayOptions, stop: threading.Event | None = None) -> dict[str, int]:
    """Publish the bag's messages from `node` with their recorded timing (scaled by options.rate) and the
    QoS they were offered with (a latched topic stays latched); return the count published per topic.
    With options.clock_hz, /clock carries the recorded time (like `ros2 bag play --clock`) and a recorded
    /clock is not replayed. Returns early when `stop` is set. The publishers stay with `node`: a latched
    message is served to late subscribers until the node is destroyed."""
    if options.rate <= 0:
        raise BagError(f'rate must be > 0, got {options.rate}')
    stop = stop or threading.Event()
    summary = info(path)
    wanted = [t.name for t in summary.topics if options.topics is None or t.name in options.topics]
    if options.clock_hz > 0:
        wanted = [t for t in wanted if t != CLOCK_TOPIC]
    if options.topics is not None:
        missing = sorted(set(options.topics) - {t.name for t in summary.topics})
        if missing:
            raise BagError(f'{path}: no topic {", ".join(missing)} in the bag '
                           f'(it has {", ".join(t.name for t in summary.topics)})')
    publishers = {}
    for t in summary.topics:
        if t.name in wanted:
            known = bag_topic(t.name)
            publishers[t.name] = node.create_publisher(
                message_class(t.type), t.name,
                replay_qos(t.offered_qos, t.name, known.offered_qos() if known else None))
    clock_pub = None
    if options.clock_hz > 0:
        from rosgraph_msgs.msg import Clock
        clock_pub = node.create_publisher(Clock, CLOCK_TOPIC, 10)
    if options.delay_s > 0 and stop.wait(options.delay_s):
        return {}
    published = {name: 0 for name in publishers}
    start_wall = time.monotonic()
    next_clock = start_wall

    def bag_time(now: float) -> int:
        return summary.start_ns + int((now - start_wall) * options.rate * 1e9)

    for message in messages(path, wanted):
        due = start_wall + (message.log_time_ns - summary.start_ns) / 1e9 / options.rate
        while True:
            now = time.monotonic()
            if clock_pub is not None and now >= next_clock:
                _publish_clock(clock_pub, min(bag_time(now), message.log_time_ns))
                next_clock = max(next_clock, now) + 1.0 / options.clock_hz     # no burst after a stall
            wait = due - now
            if clock_pub is not None:
                wait = min(wait, next_clock - now)
            if wait <= 0 and now >= due:
                break
            if stop.wait(max(wait, 0.0)):
                return published
        publishers[message.topic].publish(message.data)
        published[message.topic] += 1
    return published


def _publish_clock(pub, ns: int) -> None:
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    pub.publish(Clock(clock=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)))
