"""Write rosbag2-compatible MCAP files from raw CDR messages (no rclpy import).

The layout follows what rosbag2's MCAP storage plugin writes in Jazzy, so that the
file opens in Foxglove and in ``ros2 bag info`` / ``ros2 bag play``:

- profile ``ros2``; one schema per message type, named like ``nav_msgs/msg/Path``,
  encoding ``ros2msg``, text assembled from the installed ``.msg`` files exactly as
  rosbag2's ``LocalMessageDefinitionSource`` does (root text, then each dependency
  once, depth first in sorted order, after a line of 80 ``=`` and ``MSG: pkg/Type``);
- channels with message encoding ``cdr`` and metadata ``offered_qos_profiles`` (the
  rosbag2 version-9 YAML with policy names) and ``topic_type_hash`` (``RIHS01_...``);
- zstd-compressed chunks with message indexes and statistics in the summary.

A recording must survive its writer being killed: chunks are closed at least every
``flush_period_s`` of wall time and written straight to the file, so a reader that
scans the data section recovers every message up to the last complete chunk.
"""

from __future__ import annotations

import dataclasses
import pathlib
import re
from collections.abc import Callable, Sequence

from mcap.writer import CompressionType, Writer

from rrtq_common.settings import setting

SCENARIO_METADATA = 'rrtq_scenario'
"""Name of the MCAP metadata record that holds the scenario file (keys ``path``, ``yaml``)."""


@dataclasses.dataclass(frozen=True)
class RecorderConfig:
    """The recorder node's settings."""

    output: str = setting('run.mcap', doc='MCAP file to write')
    scenario: str = setting('', doc='scenario file to embed in the recording as MCAP metadata '
                            f'"{SCENARIO_METADATA}" (empty: none)')
    discovery_period_s: float = setting(0.05, unit='s', low=0.001,
                                        doc='wall-clock period of the topic discovery poll')
    flush_period_s: float = setting(1.0, unit='s', low=0.01,
                                    doc='close a chunk at least this often (wall clock)')

# Field types in .msg text, as rosbag2's MSG_FIELD_TYPE_REGEX matches them.
_MSG_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'})
DELIMITER = '=' * 80 + '\n'
# rmw's RMW_DURATION_INFINITE as rosbag2 writes it.
INFINITE_DURATION = (9223372036, 854775807)

MsgTextLoader = Callable[[str, str], str]
"""(package, type name) -> text of ``share/<package>/msg/<type>.msg``."""


def ament_msg_loader(package: str, type_name: str) -> str:
    """Read a ``.msg`` file from the package's share directory (the ament index)."""
    from ament_index_python.packages import get_package_share_directory
    share = pathlib.Path(get_package_share_directory(package))
    return (share / 'msg' / f'{type_name}.msg').read_text()


def _split_type(type_name: str) -> tuple[str, str]:
    parts = type_name.split('/')
    if len(parts) == 3 and parts[1] == 'msg':
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise ValueError(f'not a message type name: {type_name!r}')


def msg_dependencies(text: str, package: str) -> list[str]:
    """Non-primitive field types of a ``.msg`` text, sorted, as ``pkg/Type``."""
    deps = set()
    for match in _MSG_FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in _PRIMITIVES:
            continue
        deps.add(field_type if '/' in field_type else f'{package}/{field_type}')
    return sorted(deps)


def schema_text(type_name: str, load: MsgTextLoader = ament_msg_loader) -> str:
    """Full message definition in rosbag2's layout for ``pkg/msg/Type``."""
    seen: set[str] = set()

    def append(name: str) -> str:
        package, short = _split_type(name)
        text = load(package, short)
        out = text
        for dep in msg_dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                out += '\n' + DELIMITER + f'MSG: {dep}\n' + append(dep)
        return out

    return append(type_name)


@dataclasses.dataclass(frozen=True)
class QosOffer:
    """The policies of one publisher's offered QoS, as rmw names them."""

    history: str = 'keep_last'          # keep_last | keep_all
    depth: int = 10
    reliability: str = 'reliable'       # reliable | best_effort
    durability: str = 'volatile'        # volatile | transient_local
    deadline: tuple[int, int] = INFINITE_DURATION        # (sec, nsec)
    lifespan: tuple[int, int] = INFINITE_DURATION
    liveliness: str = 'automatic'       # automatic | manual_by_topic
    liveliness_lease_duration: tuple[int, int] = INFINITE_DURATION
    avoid_ros_namespace_conventions: bool = False


def qos_profiles_yaml(offers: Sequence[QosOffer]) -> str:
    """``offered_qos_profiles`` metadata: rosbag2's YAML (version 9) of the offers."""
    if not offers:
        return '[]'
    lines = []
    for q in offers:
        lines += [
            f'- history: {q.history}',
            f'  depth: {q.depth}',
            f'  reliability: {q.reliability}',
            f'  durability: {q.durability}',
        ]
        for name in ('deadline', 'lifespan'):
            sec, nsec = getattr(q, name)
            lines += [f'  {name}:', f'    sec: {sec}', f'    nsec: {nsec}']
        sec, nsec = q.liveliness_lease_duration
        lines += [
            f'  liveliness: {q.liveliness}',
            '  liveliness_lease_duration:', f'    sec: {sec}', f'    nsec: {nsec}',
            f'  avoid_ros_namespace_conventions: {str(q.avoid_ros_namespace_conventions).lower()}',
        ]
    return '\n'.join(lines)


class _UnbufferedFile:
    """A file whose every write reaches the OS at once (chunks survive a kill).

    Deliberately not an ``io.RawIOBase``: mcap's writer would wrap one in a buffer.
    """

    def __init__(self, path: pathlib.Path) -> None:
        self._raw = open(path, 'wb', buffering=0)  # noqa: SIM115 - closed in close()

    def write(self, data: bytes | bytearray | memoryview) -> int:
        view = memoryview(data)
        while view:
            view = view[self._raw.write(view):]
        return len(data)

    def tell(self) -> int:
        return self._raw.tell()

    def flush(self) -> None:
        """Nothing is buffered here."""

    def close(self) -> None:
        self._raw.close()


class McapRecorder:
    """Append raw CDR messages to a rosbag2-style MCAP file.

    Parameters
    ----------
    path
        Output file (created or truncated).
    chunk_size
        Bytes of uncompressed messages after which a chunk is closed.
    flush_period_s
        A chunk is also closed when this much time (``now_s`` passed to
        :meth:`write`) has passed since the last close, so a killed run loses at most
        this much.
    load
        Where ``.msg`` texts come from (the ament index by default).
    """

    def __init__(self, path: str | pathlib.Path, chunk_size: int = 1 << 20,
                 flush_period_s: float = 1.0,
                 load: MsgTextLoader = ament_msg_loader) -> None:
        self._file = _UnbufferedFile(pathlib.Path(path))
        self._writer = Writer(self._file, chunk_size=chunk_size,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library='rrtq recorder')
        self._load = load
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self._flush_period_s = flush_period_s
        self._last_flush_s: float | None = None
        self.message_count = 0
        self.byte_count = 0
        self._finished = False

    def add_topic(self, topic: str, type_name: str, offers: Sequence[QosOffer],
                  type_hash: str) -> int:
        """Register a channel for ``topic`` (once) and return its id."""
        if topic in self._channels:
            return self._channels[topic]
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding='ros2msg',
                data=schema_text(type_name, self._load).encode())
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding='cdr', schema_id=self._schemas[type_name],
            metadata={'offered_qos_profiles': qos_profiles_yaml(offers),
                      'topic_type_hash': type_hash})
        self._channels[topic] = channel_id
        self._sequence[channel_id] = 0
        return channel_id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A named MCAP metadata record (string to string map)."""
        self._writer.add_metadata(name, data)

    def has_topic(self, topic: str) -> bool:
        return topic in self._channels

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int,
              now_s: float) -> None:
        """Append one message of a registered topic."""
        channel_id = self._channels[topic]
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns,
                                 sequence=self._sequence[channel_id])
        self._sequence[channel_id] += 1
        self.message_count += 1
        self.byte_count += len(data)
        self.tick(now_s)

    def tick(self, now_s: float) -> None:
        """Close the open chunk if ``flush_period_s`` has passed since the last close."""
        if self._last_flush_s is None:
            self._last_flush_s = now_s
        elif now_s - self._last_flush_s >= self._flush_period_s:
            self._writer.flush()
            self._last_flush_s = now_s

    def finish(self) -> None:
        """Write the summary section and close the file (idempotent)."""
        if self._finished:
            return
        self._finished = True
        self._writer.finish()
        self._file.close()
