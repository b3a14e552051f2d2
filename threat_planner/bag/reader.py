"""Read MCAP recordings back: strict (indexed) or tolerant of a file cut off by a crash."""

import contextlib
import logging
import os
from pathlib import Path
from typing import Callable, Dict, Iterable, Iterator, List, NamedTuple, Optional, Union

from mcap.reader import make_reader
from mcap.records import Channel, Footer, Header, Message, Schema
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
import yaml

from threat_planner.bag.definitions import get_message_class, MESSAGE_ENCODING, SCHEMA_ENCODING
from threat_planner.errors import RecordingError

__all__ = ['RecordedMessage', 'read_messages', 'read_ros_messages', 'recorded_topics']

_LOG = logging.getLogger(__name__)

PathLike = Union[str, os.PathLike]

_MCAP_MAGIC = b'\x89MCAP0\r\n'


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
