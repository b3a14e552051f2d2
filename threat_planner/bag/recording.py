"""Record and read ROS 2 messages as MCAP files in the ``ros2`` profile.

The files are what ``ros2 bag record -s mcap`` (rosbag2, Jazzy) writes: header profile
``ros2``, one ``ros2msg`` schema per message type holding the full concatenated ``.msg``
text, ``cdr`` channels carrying ``offered_qos_profiles``, zstd-compressed chunks. A
recorder given a folder also writes a rosbag2 ``metadata.yaml`` (version 9) beside the
``.mcap``, so ``ros2 bag info`` and ``ros2 bag play`` take the folder as a bag.

Crash safety: the chunk in progress is closed and the file flushed at least once every
``flush_interval_s`` (1 s by default), by a background thread as well as on ``write``.
A process killed with SIGKILL therefore loses at most the messages of the last
``flush_interval_s`` (plus the time one chunk takes to compress and write); everything
before is in complete chunks that :func:`read_messages` with ``tolerant=True`` reads
back. Only a clean :meth:`McapRecorder.close` (or leaving the ``with`` block) writes the
summary section that strict reading and indexed tools need.

Typical use::

    with McapRecorder('out.mcap') as rec:
        rec.add_topic('/planned_path', 'nav_msgs/msg/Path', LATCHED_QOS)
        rec.write('/planned_path', path_msg, log_time_ns=stamp_ns)
    for topic, type_name, log_ns, pub_ns, msg in read_messages('out.mcap'):
        ...
"""

import contextlib
import dataclasses
import datetime
import functools
import importlib
import importlib.metadata
import json
import logging
import os
from pathlib import Path
import re
import sys
import threading
import time
from typing import Callable, Dict, Iterable, Iterator, List, NamedTuple, Optional, Union

from mcap.reader import make_reader
from mcap.records import Channel, Footer, Header, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, LIBRARY_IDENTIFIER, Writer
from mcap_ros2.decoder import DecoderFactory
import yaml

from threat_planner.bag.cdr import canonical_cdr
from threat_planner.errors import RecordingError

__all__ = [
    'INPUT_QOS',
    'LATCHED_QOS',
    'McapRecorder',
    'RecordedMessage',
    'TopicQos',
    'deserialize',
    'get_message_class',
    'message_definition',
    'message_type_name',
    'msg_dependencies',
    'read_messages',
    'read_ros_messages',
    'recorded_topics',
]

_LOG = logging.getLogger(__name__)

PathLike = Union[str, os.PathLike]

PROFILE = 'ros2'
SCHEMA_ENCODING = 'ros2msg'
MESSAGE_ENCODING = 'cdr'
METADATA_VERSION = 9
DEFAULT_CHUNK_SIZE = 256 * 1024
DEFAULT_FLUSH_INTERVAL_S = 1.0

_MCAP_MAGIC = b'\x89MCAP0\r\n'
_SEPARATOR = '=' * 80
# rmw's RMW_DURATION_INFINITE; rosbag2 records it for the unset deadline/lifespan/lease.
_INFINITE = {'sec': 9223372036, 'nsec': 854775807}
_PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))
_FIELD_TYPE = re.compile(r'[A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*){0,2}')
_TYPE_NAME = re.compile(r'^([A-Za-z][A-Za-z0-9_]*)/(?:msg/)?([A-Za-z][A-Za-z0-9_]*)$')


def _library_string() -> str:
    try:
        ours = importlib.metadata.version('threat_planner')
    except importlib.metadata.PackageNotFoundError:
        # Running from a checkout that was never installed.
        ours = 'dev'
    return f'threat_planner/{ours} {LIBRARY_IDENTIFIER}'


# --------------------------------------------------------------------------------------
# QoS
# --------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class TopicQos:
    """The QoS a topic was offered with, as rosbag2 records it.

    Parameters
    ----------
    reliability : str
        ``'reliable'``, ``'best_effort'`` or ``'system_default'``.
    durability : str
        ``'volatile'``, ``'transient_local'`` or ``'system_default'``.
    history : str
        ``'keep_last'``, ``'keep_all'`` or ``'system_default'``.
    depth : int
        History depth (ignored by readers for ``keep_all``).

    """

    reliability: str = 'reliable'
    durability: str = 'volatile'
    history: str = 'keep_last'
    depth: int = 10

    def __post_init__(self):
        """Reject values rmw would not understand, naming the bad one."""
        allowed = {
            'reliability': ('reliable', 'best_effort', 'system_default'),
            'durability': ('volatile', 'transient_local', 'system_default'),
            'history': ('keep_last', 'keep_all', 'system_default'),
        }
        for name, values in allowed.items():
            if getattr(self, name) not in values:
                raise RecordingError(
                    f'QoS {name} {getattr(self, name)!r} is not one of {", ".join(values)}')
        if isinstance(self.depth, bool) or not isinstance(self.depth, int) or self.depth < 0:
            raise RecordingError(f'QoS depth {self.depth!r} is not a non-negative integer')

    @classmethod
    def from_rclpy(cls, profile) -> 'TopicQos':
        """Convert an ``rclpy.qos.QoSProfile`` (duck-typed, so rclpy is not imported).

        Parameters
        ----------
        profile : rclpy.qos.QoSProfile
            Profile whose policies are enums named like ``RELIABLE``.

        Returns
        -------
        TopicQos
            The same policies as plain values.

        """
        return cls(reliability=profile.reliability.name.lower(),
                   durability=profile.durability.name.lower(),
                   history=profile.history.name.lower(),
                   depth=int(profile.depth))

    def as_dict(self) -> dict:
        """Return the profile as one entry of rosbag2's v9 ``offered_qos_profiles`` list.

        Returns
        -------
        dict
            Keys in rosbag2's order, with string enums and infinite durations.

        """
        return {
            'history': self.history,
            'depth': self.depth,
            'reliability': self.reliability,
            'durability': self.durability,
            'deadline': dict(_INFINITE),
            'lifespan': dict(_INFINITE),
            'liveliness': 'automatic',
            'liveliness_lease_duration': dict(_INFINITE),
            'avoid_ros_namespace_conventions': False,
        }

    def to_yaml(self) -> str:
        """Return the YAML string rosbag2 stores in the MCAP channel metadata.

        Returns
        -------
        str
            A one-element YAML sequence.

        """
        return yaml.safe_dump([self.as_dict()], sort_keys=False, default_flow_style=False)


#: Outputs the planner latches: late subscribers still get the last plan.
LATCHED_QOS = TopicQos(reliability='reliable', durability='transient_local',
                       history='keep_last', depth=1)
#: Inputs and other streams: reliable, volatile.
INPUT_QOS = TopicQos(reliability='reliable', durability='volatile',
                     history='keep_last', depth=10)


def _as_topic_qos(qos) -> TopicQos:
    if qos is None:
        return INPUT_QOS
    if isinstance(qos, TopicQos):
        return qos
    if all(hasattr(qos, a) for a in ('reliability', 'durability', 'history', 'depth')):
        return TopicQos.from_rclpy(qos)
    raise RecordingError(f'qos {qos!r} is neither a TopicQos nor an rclpy QoSProfile')


# --------------------------------------------------------------------------------------
# Message definitions and classes
# --------------------------------------------------------------------------------------

def _split_type(type_name: str):
    match = _TYPE_NAME.match(type_name or '')
    if match is None:
        raise RecordingError(
            f'message type {type_name!r} is not of the form pkg/msg/Type or pkg/Type')
    return match.group(1), match.group(2)


def _canonical(type_name: str) -> str:
    package, name = _split_type(type_name)
    return f'{package}/msg/{name}'


def _share_dirs(package: str) -> List[Path]:
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory
        dirs.append(Path(get_package_share_directory(package, print_warning=False)))
    except (ImportError, LookupError, OSError, ValueError):
        # A pip-only install has no AMENT_PREFIX_PATH; the wheels still put the
        # interface files under the environment prefix.
        pass
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix)):
        dirs.append(Path(prefix) / 'share' / package)
    return dirs


def _interface_file(type_name: str, suffix: str) -> Optional[Path]:
    package, name = _split_type(type_name)
    for share in _share_dirs(package):
        candidate = share / 'msg' / f'{name}{suffix}'
        if candidate.is_file():
            return candidate
    return None


def _load_msg_text(type_name: str) -> str:
    path = _interface_file(type_name, '.msg')
    if path is None:
        package, name = _split_type(type_name)
        raise RecordingError(
            f'no {name}.msg for {type_name} under the share/{package}/msg of the ament '
            f'index or {sys.prefix}; is the {package} package installed?')
    return path.read_text(encoding='utf-8')


def msg_dependencies(text: str, package: str) -> List[str]:
    """List the non-primitive field types of one ``.msg`` text, as rosbag2 does.

    Comments, blank lines and constants (``int32 X=1``) are skipped by looking only at
    each line's leading type token; array (``[]``, ``[N]``, ``[<=N]``) and string bound
    (``<=N``) suffixes are dropped. A bare ``Type`` means ``package/Type``, except
    ``Header`` which is ``std_msgs/Header``; ``pkg/msg/Type`` is shortened to
    ``pkg/Type``.

    Parameters
    ----------
    text : str
        Contents of a ``.msg`` file.
    package : str
        Package the file belongs to, for bare type names.

    Returns
    -------
    list of str
        Sorted, unique ``pkg/Type`` names (rosbag2 keeps them in a ``std::set``).

    """
    found = set()
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        match = _FIELD_TYPE.match(line)
        if match is None:
            continue
        base = match.group(0)
        if base in _PRIMITIVES:
            continue
        parts = base.split('/')
        if len(parts) == 1:
            found.add('std_msgs/Header' if base == 'Header' else f'{package}/{base}')
        else:
            found.add(f'{parts[0]}/{parts[-1]}')
    return sorted(found)


def _build_definition(type_name: str, load_text: Callable[[str], str]) -> str:
    # Same layout and order as rosbag2_storage_mcap's MessageDefinitionCache: the root
    # text, then depth-first each dependency once, behind an 80-'=' line and 'MSG: pkg/T'.
    seen = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise RecordingError(f'message definition of {type_name} nests too deep')
        package, _ = _split_type(name)
        text = load_text(_canonical(name))
        result = text
        for dep in msg_dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                result += f'\n{_SEPARATOR}\nMSG: {dep}\n' + append(dep, depth - 1)
        return result

    return append(_canonical(type_name), 50)


_DEFINITIONS: Dict[str, str] = {}
_DEFINITIONS_LOCK = threading.Lock()


def message_definition(type_name: str) -> str:
    """Return the full ``ros2msg`` schema text of a message type, as rosbag2 writes it.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` or ``pkg/Type``.

    Returns
    -------
    str
        The type's ``.msg`` text followed by each dependency's block.

    Raises
    ------
    RecordingError
        If a ``.msg`` file of the type or of a dependency cannot be found.

    """
    key = _canonical(type_name)
    with _DEFINITIONS_LOCK:
        if key not in _DEFINITIONS:
            _DEFINITIONS[key] = _build_definition(key, _load_msg_text)
        return _DEFINITIONS[key]


@functools.lru_cache(maxsize=None)
def _type_hash(type_name: str) -> str:
    # rosidl installs <Type>.json next to <Type>.msg with the RIHS01 hash rosbag2 records;
    # an empty hash is what rosbag2 writes when it has none.
    path = _interface_file(type_name, '.json')
    if path is None:
        return ''
    try:
        entries = json.loads(path.read_text(encoding='utf-8')).get('type_hashes', [])
        return next((e['hash_string'] for e in entries
                     if e.get('type_name') == _canonical(type_name)), '')
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return ''


def message_type_name(msg) -> str:
    """Return ``pkg/msg/Type`` of an rclpy message object.

    Parameters
    ----------
    msg : object
        Instance of a generated ROS 2 message class.

    Returns
    -------
    str
        The ROS type name.

    Raises
    ------
    RecordingError
        If ``msg`` is not a generated message.

    """
    cls = type(msg)
    module = cls.__module__.split('.')
    if len(module) < 2 or module[1] != 'msg' or not hasattr(cls, '_TYPE_SUPPORT'):
        raise RecordingError(f'{cls.__name__} object is not a generated ROS 2 message')
    return f'{module[0]}/msg/{cls.__name__}'


def get_message_class(type_name: str):
    """Import the rclpy message class of a type.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` or ``pkg/Type``.

    Returns
    -------
    type
        The generated message class.

    Raises
    ------
    RecordingError
        If the package or type is not installed.

    """
    canonical = _canonical(type_name)
    try:
        from rosidl_runtime_py.utilities import get_message
    except ImportError:
        get_message = None
    try:
        if get_message is not None:
            return get_message(canonical)
        package, name = _split_type(canonical)
        return getattr(importlib.import_module(f'{package}.msg'), name)
    except (ImportError, AttributeError, ValueError) as exc:
        raise RecordingError(f'message type {canonical} is not installed: {exc}') from exc


def deserialize(data: bytes, type_name: str):
    """Deserialise CDR bytes to an rclpy message, e.g. for replay.

    Parameters
    ----------
    data : bytes
        CDR payload as recorded.
    type_name : str
        ``pkg/msg/Type`` of the payload.

    Returns
    -------
    object
        Instance of the generated message class.

    Raises
    ------
    RecordingError
        If the type is unknown or the bytes are not a valid message of it.

    """
    from rclpy.serialization import deserialize_message
    cls = get_message_class(type_name)
    try:
        return deserialize_message(bytes(data), cls)
    except Exception as exc:  # noqa: B902 - the C layer raises assorted types on bad CDR
        raise RecordingError(f'bytes are not a valid {_canonical(type_name)}: {exc}') from exc


# --------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------

@dataclasses.dataclass
class _Topic:
    type_name: str
    qos: TopicQos
    channel_id: int
    count: int = 0


class McapRecorder:
    """Write ROS 2 messages to an MCAP file (a context manager; always finishes the file).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.mcap`` file to create (overwritten if present), or a folder (an existing
        directory or a path without the ``.mcap`` suffix) in which a bag directory
        ``<prefix>_<YYYYmmdd-HHMMSS>/`` is created holding ``<that name>_0.mcap`` and a
        rosbag2 ``metadata.yaml``.
    prefix : str
        Name prefix of the bag directory in folder mode.
    chunk_size : int
        Uncompressed bytes after which a chunk is closed regardless of time.
    flush_interval_s : float or None
        Longest time a message waits in memory before its chunk is written and the file
        flushed; this bounds what a SIGKILL loses. ``None`` or ``0`` disables the timer
        (then only ``chunk_size``, :meth:`flush` and :meth:`close` write chunks).

    Raises
    ------
    RecordingError
        If the file or directory cannot be created.

    """

    def __init__(self, path: PathLike, *, prefix: str = 'threat_planner',
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_interval_s: Optional[float] = DEFAULT_FLUSH_INTERVAL_S):
        target = Path(path)
        self._bag_dir: Optional[Path] = None
        try:
            if target.is_dir() or target.suffix.lower() != '.mcap':
                self._bag_dir = self._make_bag_dir(target, prefix)
                self._path = self._bag_dir / f'{self._bag_dir.name}_0.mcap'
            else:
                target.parent.mkdir(parents=True, exist_ok=True)
                self._path = target
            self._stream = open(self._path, 'wb')
        except OSError as exc:
            raise RecordingError(f'{path}: cannot create recording: {exc.strerror or exc}') \
                from exc
        self._lock = threading.RLock()
        self._writer = Writer(self._stream, chunk_size=int(chunk_size),
                              compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=_library_string())
        self._stream.flush()
        self._schemas: Dict[str, int] = {}
        self._topics: Dict[str, _Topic] = {}
        self._count = 0
        self._start_ns: Optional[int] = None
        self._end_ns: Optional[int] = None
        self._pending = 0
        self._closed = False
        self._interval = float(flush_interval_s) if flush_interval_s else 0.0
        self._last_flush = time.monotonic()
        self._stop = threading.Event()
        self._flusher: Optional[threading.Thread] = None
        if self._interval > 0:
            # A timer, not only write(), so a topic that goes quiet is still on disk
            # within one interval.
            self._flusher = threading.Thread(target=self._flush_loop, daemon=True,
                                             name=f'mcap-flush-{self._path.name}')
            self._flusher.start()
        if self._bag_dir is not None:
            self._write_metadata()

    @staticmethod
    def _make_bag_dir(folder: Path, prefix: str) -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        stamp = datetime.datetime.now().strftime('%Y%m%d-%H%M%S')
        for attempt in range(1000):
            name = f'{prefix}_{stamp}' + (f'_{attempt}' if attempt else '')
            try:
                (folder / name).mkdir()
            except FileExistsError:
                # Two recorders started in the same second each get their own bag.
                continue
            return folder / name
        raise RecordingError(f'{folder}: no free bag directory name for {prefix}_{stamp}')

    # -- properties -------------------------------------------------------------------

    @property
    def path(self) -> Path:
        """Path of the ``.mcap`` file being written."""
        return self._path

    @property
    def bag_dir(self) -> Optional[Path]:
        """The rosbag2 directory in folder mode, else ``None``."""
        return self._bag_dir

    @property
    def message_count(self) -> int:
        """Number of messages written so far."""
        return self._count

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    # -- writing ----------------------------------------------------------------------

    def add_topic(self, topic: str, type_name: str, qos=None) -> None:
        """Register a topic, its type and offered QoS before (or without) writing to it.

        Parameters
        ----------
        topic : str
            Topic name, e.g. ``/planned_path``.
        type_name : str
            ``pkg/msg/Type`` (``pkg/Type`` accepted).
        qos : TopicQos or rclpy.qos.QoSProfile, optional
            Offered QoS; :data:`INPUT_QOS` if omitted.

        Raises
        ------
        RecordingError
            If the topic exists with another type, or the type's ``.msg`` is missing.

        """
        with self._lock:
            self._check_open()
            self._topic(topic, _canonical(type_name), qos)

    def write(self, topic: str, msg, type_name: Optional[str] = None,
              log_time_ns: Optional[int] = None, publish_time_ns: Optional[int] = None,
              qos=None) -> None:
        """Append one message, registering its schema and channel on first use.

        Parameters
        ----------
        topic : str
            Topic name.
        msg : object or bytes
            An rclpy message (serialised here to CDR) or already serialised CDR bytes.
        type_name : str, optional
            ``pkg/msg/Type``; taken from ``msg`` if it is a message object, required
            for bytes on a topic not yet registered.
        log_time_ns : int, optional
            Receive/record time in ns since the epoch; now if omitted.
        publish_time_ns : int, optional
            Publish time in ns; ``log_time_ns`` if omitted.
        qos : TopicQos or rclpy.qos.QoSProfile, optional
            Offered QoS, used only when this call registers the topic.

        Raises
        ------
        RecordingError
            If the recorder is closed, the type is missing or inconsistent, a time is
            negative, or the message cannot be serialised.

        """
        if isinstance(msg, (bytes, bytearray, memoryview)):
            data = bytes(msg)
        else:
            msg_type = message_type_name(msg)
            if type_name is not None and _canonical(type_name) != msg_type:
                raise RecordingError(
                    f'{topic}: message is a {msg_type}, not the given {type_name}')
            type_name = msg_type
            data = self._serialize(topic, msg)
        log_time_ns = time.time_ns() if log_time_ns is None else log_time_ns
        publish_time_ns = log_time_ns if publish_time_ns is None else publish_time_ns
        for label, value in (('log_time_ns', log_time_ns), ('publish_time_ns', publish_time_ns)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise RecordingError(f'{topic}: {label} {value!r} is not a non-negative int')
        with self._lock:
            self._check_open()
            entry = self._topics.get(topic)
            if entry is None:
                if type_name is None:
                    raise RecordingError(
                        f'{topic}: type_name is needed to record bytes on a new topic')
                entry = self._topic(topic, _canonical(type_name), qos)
            elif type_name is not None and _canonical(type_name) != entry.type_name:
                raise RecordingError(
                    f'{topic}: recorded as {entry.type_name}, cannot add a {type_name}')
            try:
                self._writer.add_message(channel_id=entry.channel_id, log_time=log_time_ns,
                                         data=data, publish_time=publish_time_ns,
                                         sequence=entry.count + 1)
            except OSError as exc:
                # A full chunk is written inside add_message, so the disk shows up here.
                raise RecordingError(f'{self._path}: cannot write: {exc}') from exc
            entry.count += 1
            self._count += 1
            self._pending += 1
            self._start_ns = log_time_ns if self._start_ns is None else min(
                self._start_ns, log_time_ns)
            self._end_ns = log_time_ns if self._end_ns is None else max(
                self._end_ns, log_time_ns)
            if self._interval > 0 and time.monotonic() - self._last_flush >= self._interval:
                self._flush_locked()

    def flush(self) -> None:
        """Close the chunk in progress and flush the file (not fsync)."""
        with self._lock:
            self._check_open()
            self._flush_locked()

    def close(self) -> None:
        """Finish the file (summary, footer) and write ``metadata.yaml``; idempotent.

        Raises
        ------
        RecordingError
            If the file cannot be finished (the stream is closed regardless).

        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._stop.set()
        if self._flusher is not None and self._flusher is not threading.current_thread():
            self._flusher.join()
        with self._lock:
            try:
                self._writer.finish()
                self._stream.flush()
            except (OSError, ValueError) as exc:
                raise RecordingError(f'{self._path}: cannot finish recording: {exc}') from exc
            finally:
                self._stream.close()
                if self._bag_dir is not None:
                    self._write_metadata()

    def __enter__(self) -> 'McapRecorder':
        """Return the recorder itself."""
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Close the recorder, also when the block raised."""
        self.close()

    # -- internals --------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f'{self._path}: recorder is closed')

    @staticmethod
    def _serialize(topic: str, msg) -> bytes:
        from rclpy.serialization import serialize_message
        try:
            data = serialize_message(msg)
        except Exception as exc:  # noqa: B902 - rclpy's C layer raises assorted types
            raise RecordingError(f'{topic}: cannot serialise {type(msg).__name__}: {exc}') \
                from exc
        # rclpy's buffer has trailing bytes and uninitialised padding (see bag/cdr.py).
        type_name = message_type_name(msg)
        try:
            return canonical_cdr(data, type_name, message_definition(type_name))
        except RecordingError as exc:
            raise RecordingError(f'{topic}: {exc}') from exc

    def _topic(self, topic: str, type_name: str, qos) -> _Topic:
        entry = self._topics.get(topic)
        if entry is not None:
            if entry.type_name != type_name:
                raise RecordingError(
                    f'{topic}: recorded as {entry.type_name}, cannot add a {type_name}')
            return entry
        qos = _as_topic_qos(qos)
        schema_id = self._schemas.get(type_name)
        if schema_id is None:
            text = message_definition(type_name)
            schema_id = self._writer.register_schema(
                name=type_name, encoding=SCHEMA_ENCODING, data=text.encode('utf-8'))
            self._schemas[type_name] = schema_id
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id,
            metadata={'offered_qos_profiles': qos.to_yaml(),
                      'topic_type_hash': _type_hash(type_name)})
        entry = _Topic(type_name=type_name, qos=qos, channel_id=channel_id)
        self._topics[topic] = entry
        return entry

    def _flush_loop(self) -> None:
        while True:
            with self._lock:
                due = self._last_flush + self._interval
            # Wake exactly when the interval since the last flush (by write() or by this
            # thread) ends, so no message waits longer than one interval.
            if self._stop.wait(max(0.0, due - time.monotonic())):
                return
            with self._lock:
                if self._closed:
                    return
                if time.monotonic() - self._last_flush >= self._interval:
                    try:
                        self._flush_locked()
                    except RecordingError:
                        # Disk full or similar: close() reports it; a dying timer thread
                        # must not take the process down with it.
                        _LOG.exception('periodic flush of %s failed', self._path)
                        return

    def _flush_locked(self) -> None:
        try:
            if self._pending:
                finish_chunk = getattr(self._writer, 'flush', None)
                if finish_chunk is None:
                    # mcap releases without Writer.flush(): end the chunk through the
                    # private method, which is what flush() does.
                    self._writer._Writer__finalize_chunk()
                else:
                    finish_chunk()
            self._stream.flush()
        except OSError as exc:
            raise RecordingError(f'{self._path}: cannot write: {exc}') from exc
        self._last_flush = time.monotonic()
        if self._pending and self._bag_dir is not None:
            # Keeps a killed bag playable with counts up to the last flush.
            self._write_metadata()
        self._pending = 0

    def _write_metadata(self) -> None:
        start = self._start_ns or 0
        duration = (self._end_ns - self._start_ns) if self._count else 0
        name = self._path.name
        info = {
            'version': METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': self._count,
            'topics_with_message_count': [
                {
                    'topic_metadata': {
                        'name': topic,
                        'type': entry.type_name,
                        'serialization_format': MESSAGE_ENCODING,
                        'offered_qos_profiles': [entry.qos.as_dict()],
                        'type_description_hash': _type_hash(entry.type_name),
                    },
                    'message_count': entry.count,
                }
                for topic, entry in self._topics.items()
            ],
            # Chunk compression is internal to MCAP; rosbag2 leaves these empty for it.
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [name],
            'files': [{
                'path': name,
                'starting_time': {'nanoseconds_since_epoch': start},
                'duration': {'nanoseconds': duration},
                'message_count': self._count,
            }],
            'custom_data': None,
            'ros_distro': os.environ.get('ROS_DISTRO', 'jazzy'),
        }
        text = yaml.safe_dump({'rosbag2_bagfile_information': info}, sort_keys=False,
                              default_flow_style=False)
        target = self._bag_dir / 'metadata.yaml'
        tmp = target.with_suffix('.yaml.tmp')
        try:
            tmp.write_text(text, encoding='utf-8')
            os.replace(tmp, target)
        except OSError as exc:
            raise RecordingError(f'{target}: cannot write bag metadata: {exc}') from exc


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------

class RecordedMessage(NamedTuple):
    """One message read back from a recording."""

    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    msg: object


def _one_line(exc: BaseException) -> str:
    text = ' '.join(str(exc).split()) or type(exc).__name__
    text = text if len(text) <= 160 else text[:157] + '...'
    return f'{type(exc).__name__}: {text}'


def _mcap_files(path: Path) -> List[Path]:
    if not path.is_dir():
        return [path]
    meta = path / 'metadata.yaml'
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text(encoding='utf-8'))
            names = info['rosbag2_bagfile_information']['relative_file_paths']
            return [path / Path(n).name for n in names]
        except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
            raise RecordingError(f'{meta}: not a rosbag2 metadata file ({_one_line(exc)})') \
                from exc
    files = sorted(path.glob('*.mcap'))
    if not files:
        raise RecordingError(f'{path}: directory holds no .mcap file')
    return files


def _check_channel(path: Path, channel: Channel, schema: Optional[Schema]) -> None:
    if channel.message_encoding != MESSAGE_ENCODING:
        raise RecordingError(
            f'{path}: topic {channel.topic} has message encoding '
            f'{channel.message_encoding!r}; only {MESSAGE_ENCODING!r} is supported')
    encoding = schema.encoding if schema is not None else ''
    if encoding != SCHEMA_ENCODING:
        raise RecordingError(
            f'{path}: topic {channel.topic} has schema encoding {encoding!r}; only '
            f'{SCHEMA_ENCODING!r} (ROS 2 .msg text) is supported')


class _Decoder:
    """Turns (schema, channel, message) records into RecordedMessage, per file."""

    def __init__(self, path: Path, ros_classes: bool):
        self._path = path
        self._ros = ros_classes
        self._factory = DecoderFactory()
        self._decoders: Dict[int, Callable[[bytes], object]] = {}

    def __call__(self, schema: Optional[Schema], channel: Channel,
                 message: Message) -> RecordedMessage:
        decode = self._decoders.get(channel.id)
        if decode is None:
            _check_channel(self._path, channel, schema)
            if self._ros:
                try:
                    cls = get_message_class(schema.name)
                except RecordingError as exc:
                    raise RecordingError(f'{self._path}: {exc}') from exc

                def decode(data, cls=cls):
                    from rclpy.serialization import deserialize_message
                    return deserialize_message(bytes(data), cls)
            else:
                try:
                    decode = self._factory.decoder_for(channel.message_encoding, schema)
                except Exception as exc:  # noqa: B902 - parser errors have many types
                    raise RecordingError(
                        f'{self._path}: schema {schema.name} of {channel.topic} does not '
                        f'parse ({_one_line(exc)})') from exc
            self._decoders[channel.id] = decode
        try:
            msg = decode(message.data)
        except Exception as exc:  # noqa: B902 - a bad payload can fail in many ways
            raise RecordingError(
                f'{self._path}: message on {channel.topic} at {message.log_time} ns is not '
                f'a valid {schema.name} ({_one_line(exc)})') from exc
        return RecordedMessage(channel.topic, schema.name, message.log_time,
                               message.publish_time, msg)


def _iter_strict(path: Path, topics, decoder: _Decoder) -> Iterator[RecordedMessage]:
    try:
        stream = open(path, 'rb')
    except OSError as exc:
        raise RecordingError(f'{path}: cannot open ({exc.strerror or exc})') from exc
    with stream:
        try:
            head = stream.read(len(_MCAP_MAGIC))
            if head != _MCAP_MAGIC:
                raise RecordingError(f'{path}: not an MCAP file (bad magic)')
            stream.seek(-len(_MCAP_MAGIC), os.SEEK_END)
            if stream.tell() < len(_MCAP_MAGIC) or stream.read() != _MCAP_MAGIC:
                raise RecordingError(
                    f'{path}: truncated MCAP file (no footer; the recorder did not close '
                    'it - read with tolerant=True to get the complete chunks)')
            stream.seek(0)
            reader = make_reader(stream, validate_crcs=True)
            summary = reader.get_summary()
            if summary is not None:
                for channel in summary.channels.values():
                    _check_channel(path, channel, summary.schemas.get(channel.schema_id))
            records = reader.iter_messages(topics=topics, log_time_order=True)
        except RecordingError:
            raise
        except Exception as exc:  # noqa: B902 - corrupt input fails in many ways
            raise RecordingError(f'{path}: corrupt MCAP file ({_one_line(exc)})') from exc
        while True:
            try:
                schema, channel, message = next(records)
            except StopIteration:
                return
            except RecordingError:
                raise
            except Exception as exc:  # noqa: B902 - corrupt chunks fail in many ways
                raise RecordingError(f'{path}: corrupt MCAP file ({_one_line(exc)})') from exc
            yield decoder(schema, channel, message)


@contextlib.contextmanager
def _records_after_header(path: Path) -> Iterator[Iterator[object]]:
    """Open an MCAP file as a record stream positioned after its checked header."""
    try:
        stream = open(path, 'rb')
    except OSError as exc:
        raise RecordingError(f'{path}: cannot open ({exc.strerror or exc})') from exc
    with stream:
        records = StreamReader(stream, validate_crcs=True).records
        try:
            header = next(records)
        except Exception as exc:  # noqa: B902 - anything but a header means not MCAP
            raise RecordingError(f'{path}: not an MCAP file ({_one_line(exc)})') from exc
        if not isinstance(header, Header):
            raise RecordingError(f'{path}: not an MCAP file (no header record)')
        yield records


def _iter_tolerant(path: Path, topics, decoder: _Decoder) -> Iterator[RecordedMessage]:
    with _records_after_header(path) as records:
        schemas: Dict[int, Schema] = {}
        channels: Dict[int, Channel] = {}
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception as exc:  # noqa: B902 - the cut-off tail fails in many ways
                # Expected after a crash: the last chunk or index was cut off mid-write.
                _LOG.warning('%s: stopped reading at a truncated or corrupt record (%s)',
                             path, _one_line(exc))
                return
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
                _check_channel(path, record, schemas.get(record.schema_id))
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None:
                    raise RecordingError(
                        f'{path}: message on unknown channel {record.channel_id}')
                if topics is None or channel.topic in topics:
                    yield decoder(schemas.get(channel.schema_id), channel, record)
            elif isinstance(record, Footer):
                return


def _iter_recording(path: PathLike, tolerant: bool, topics: Optional[Iterable[str]],
                    ros_classes: bool) -> Iterator[RecordedMessage]:
    wanted = None if topics is None else ({topics} if isinstance(topics, str) else set(topics))
    for file in _mcap_files(Path(path)):
        decoder = _Decoder(file, ros_classes)
        if tolerant:
            yield from _iter_tolerant(file, wanted, decoder)
        else:
            yield from _iter_strict(file, wanted, decoder)


def _stream_channels(path: Path) -> List[tuple]:
    channels: List[tuple] = []
    schemas: Dict[int, Schema] = {}
    with _records_after_header(path) as records:
        while True:
            try:
                record = next(records)
            except Exception:  # noqa: B902 - StopIteration, or a cut-off tail
                return channels
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                _check_channel(path, record, schemas.get(record.schema_id))
                channels.append((record, schemas.get(record.schema_id)))
            elif isinstance(record, Footer):
                return channels


def recorded_topics(path: PathLike, *, tolerant: bool = False) -> Dict[str, str]:
    """Return the topics of a recording and their types, without decoding any message.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.mcap`` file or a bag directory.
    tolerant : bool
        As in :func:`read_messages`: ``True`` accepts a file cut off by a crash (the
        channels written before the cut are listed).

    Returns
    -------
    dict[str, str]
        ``{topic: 'pkg/msg/Type'}`` in the order the channels were recorded.

    Raises
    ------
    RecordingError
        As :func:`read_messages` (missing, non-MCAP, truncated in strict mode, corrupt,
        or a channel that is not ``cdr``/``ros2msg``).

    """
    topics: Dict[str, str] = {}
    for file in _mcap_files(Path(path)):
        channels = None
        if not tolerant:
            # Checks magic, footer, summary and channel encodings; reads no chunk.
            for _ in _iter_strict(file, frozenset(), _Decoder(file, False)):
                pass
            with open(file, 'rb') as stream:
                summary = make_reader(stream).get_summary()
            if summary is not None:
                channels = [(c, summary.schemas.get(c.schema_id))
                            for c in sorted(summary.channels.values(), key=lambda c: c.id)]
        if channels is None:
            channels = _stream_channels(file)
        for channel, schema in channels:
            topics.setdefault(channel.topic, schema.name if schema is not None else '')
    return topics


def read_messages(path: PathLike, *, tolerant: bool = False,
                  topics: Optional[Iterable[str]] = None) -> Iterator[RecordedMessage]:
    """Read a recording, decoding payloads with ``mcap_ros2``'s ``ros2msg`` decoder.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.mcap`` file, or a bag directory (its ``metadata.yaml`` lists the files).
    tolerant : bool
        ``False``: the file must be complete (footer present, every CRC right);
        messages come in log-time order. ``True``: read in file order and stop
        quietly (a logged warning) at a truncated or corrupt tail, as left by a
        killed recorder; a file that is not MCAP at all still raises.
    topics : iterable of str, optional
        Only these topics.

    Returns
    -------
    iterator of RecordedMessage
        ``(topic, type_name, log_time_ns, publish_time_ns, msg)`` with ``msg`` a
        dynamic object whose attributes are the message fields.

    Raises
    ------
    RecordingError
        With a one-line message naming the file, for a missing, non-MCAP, truncated
        (strict mode) or corrupt file, or a channel that is not ``cdr``/``ros2msg``.

    """
    return _iter_recording(path, tolerant, topics, ros_classes=False)


def read_ros_messages(path: PathLike, *, tolerant: bool = False,
                      topics: Optional[Iterable[str]] = None) -> Iterator[RecordedMessage]:
    """Read a recording into real rclpy message objects, for replay.

    Same as :func:`read_messages` except that ``msg`` is an instance of the generated
    class (``rclpy.serialization.deserialize_message``), ready to publish.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.mcap`` file or a bag directory.
    tolerant : bool
        Stop quietly at a truncated tail instead of raising.
    topics : iterable of str, optional
        Only these topics.

    Returns
    -------
    iterator of RecordedMessage
        With rclpy message objects.

    Raises
    ------
    RecordingError
        As :func:`read_messages`, and when a recorded type is not installed.

    """
    return _iter_recording(path, tolerant, topics, ros_classes=True)
