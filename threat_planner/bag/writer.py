"""Write ROS 2 messages to MCAP in the ``ros2`` profile: :class:`McapRecorder`.

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

import dataclasses
import datetime
import logging
import os
from pathlib import Path
import threading
import time
from typing import Dict, Optional, Union

from mcap.writer import CompressionType, LIBRARY_IDENTIFIER, Writer

from threat_planner._version import __version__
from threat_planner.bag.cdr import serialize_cdr
from threat_planner.bag.definitions import (canonical_type_name, MESSAGE_ENCODING,
                                            message_definition, message_type_name, PROFILE,
                                            SCHEMA_ENCODING, type_description_hash)
from threat_planner.bag.metadata import (bag_information, file_entry, io_reason, topic_entry,
                                         write_bag_metadata)
from threat_planner.bag.qos import as_topic_qos, TopicQos
from threat_planner.errors import RecordingError

__all__ = ['DEFAULT_FLUSH_INTERVAL_S', 'McapRecorder']

_LOG = logging.getLogger(__name__)

PathLike = Union[str, os.PathLike]

DEFAULT_CHUNK_SIZE = 256 * 1024
DEFAULT_FLUSH_INTERVAL_S = 1.0


def _library_string() -> str:
    return f'threat_planner/{__version__} {LIBRARY_IDENTIFIER}'


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
        # Set by the first I/O error: from then on nothing more is written, and close()
        # only releases the file instead of raising the same error again.
        self._failed: Optional[str] = None
        self._schemas: Dict[str, int] = {}
        self._topics: Dict[str, _Topic] = {}
        self._count = 0
        self._start_ns: Optional[int] = None
        self._end_ns: Optional[int] = None
        self._pending = 0
        self._closed = False
        self._writer = Writer(self._stream, chunk_size=int(chunk_size),
                              compression=CompressionType.ZSTD)
        try:
            self._writer.start(profile=PROFILE, library=_library_string())
            self._stream.flush()
            if self._bag_dir is not None:
                self._write_metadata()
        except (OSError, RecordingError) as exc:
            self._release()
            raise RecordingError(f'{path}: cannot create recording: {io_reason(exc)}') \
                from exc
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
            self._topic(topic, canonical_type_name(type_name), qos)

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
            if type_name is not None and canonical_type_name(type_name) != msg_type:
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
                entry = self._topic(topic, canonical_type_name(type_name), qos)
            elif type_name is not None and canonical_type_name(type_name) != entry.type_name:
                raise RecordingError(
                    f'{topic}: recorded as {entry.type_name}, cannot add a {type_name}')
            try:
                self._writer.add_message(channel_id=entry.channel_id, log_time=log_time_ns,
                                         data=data, publish_time=publish_time_ns,
                                         sequence=entry.count + 1)
            except (OSError, ValueError) as exc:
                # A full chunk is written inside add_message, so the disk shows up here.
                raise self._fail('cannot write', exc) from exc
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
            if self._failed is not None:
                # Already reported; the chunks written before the failure stay readable
                # with the tolerant reader (or `threat-planner bag repair`).
                self._release()
                return
            try:
                self._writer.finish()
                self._stream.flush()
                self._stream.close()
                if self._bag_dir is not None:
                    self._write_metadata()
            except (OSError, ValueError, RecordingError) as exc:
                self._release()
                raise self._fail('cannot finish recording', exc) from exc

    def __enter__(self) -> 'McapRecorder':
        """Return the recorder itself."""
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Close the recorder, also when the block raised."""
        self.close()

    # -- internals --------------------------------------------------------------------

    @property
    def failed(self) -> Optional[str]:
        """The first I/O error (the recording stopped there), or None."""
        return self._failed

    def _check_open(self) -> None:
        if self._failed is not None:
            raise RecordingError(f'{self._path}: recording stopped after: {self._failed}')
        if self._closed:
            raise RecordingError(f'{self._path}: recorder is closed')

    def _fail(self, what: str, exc: BaseException) -> RecordingError:
        """Remember the first I/O error and return the error to raise for it."""
        if self._failed is None:
            self._failed = f'{what}: {io_reason(exc)}'
        return RecordingError(f'{self._path}: {what}: {io_reason(exc)}')

    def _release(self) -> None:
        """Close the file without writing more; buffered bytes that cannot go are lost."""
        try:
            self._stream.close()
        except (OSError, ValueError):
            # BufferedWriter.close retries the failed flush, then closes the descriptor
            # regardless: the error was reported once already.
            pass

    @staticmethod
    def _serialize(topic: str, msg) -> bytes:
        return serialize_cdr(msg, topic)

    def _topic(self, topic: str, type_name: str, qos) -> _Topic:
        entry = self._topics.get(topic)
        if entry is not None:
            if entry.type_name != type_name:
                raise RecordingError(
                    f'{topic}: recorded as {entry.type_name}, cannot add a {type_name}')
            return entry
        qos = as_topic_qos(qos)
        schema_id = self._schemas.get(type_name)
        try:
            if schema_id is None:
                text = message_definition(type_name)
                schema_id = self._writer.register_schema(
                    name=type_name, encoding=SCHEMA_ENCODING, data=text.encode('utf-8'))
                self._schemas[type_name] = schema_id
            channel_id = self._writer.register_channel(
                topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id,
                metadata={'offered_qos_profiles': qos.to_yaml(),
                          'topic_type_hash': type_description_hash(type_name)})
        except (OSError, ValueError) as exc:
            raise self._fail('cannot write', exc) from exc
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
                    except RecordingError as exc:
                        # Disk full or similar: the next write() raises it to the owner,
                        # who reports it once; this thread only stops.
                        _LOG.debug('periodic flush stopped: %s', exc)
                        return

    def _flush_locked(self) -> None:
        if self._failed is not None:
            raise RecordingError(f'{self._path}: recording stopped after: {self._failed}')
        try:
            if self._pending:
                # mcap >= 1.6 (setup.py): ends the chunk in progress and writes it out.
                self._writer.flush()
            self._stream.flush()
            if self._pending and self._bag_dir is not None:
                # Keeps a killed bag playable with counts up to the last flush.
                self._write_metadata()
        except (OSError, ValueError, RecordingError) as exc:
            raise self._fail('cannot write', exc) from exc
        self._last_flush = time.monotonic()
        self._pending = 0

    def _write_metadata(self) -> None:
        topics = [topic_entry(topic, e.type_name, MESSAGE_ENCODING, [e.qos.as_dict()],
                              type_description_hash(e.type_name), e.count)
                  for topic, e in self._topics.items()]
        files = [file_entry(self._path.name, self._start_ns, self._end_ns, self._count)]
        write_bag_metadata(self._bag_dir, bag_information(topics, files))
