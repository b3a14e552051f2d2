"""Rewrite a damaged MCAP recording (cut off by SIGKILL or power loss) as a complete file.

A recorder killed mid-write leaves a file without summary or footer: the tolerant reader
of :mod:`threat_planner.bag.reader` reads it, indexed readers (``rosbags``, mcap's
seeking reader, ``ros2 bag``) do not. :func:`repair_recording` reads the file record by
record, keeps everything up to the first record that is cut off or fails its CRC (every
complete chunk, with the schemas, channels, metadata and attachments seen so far) and
writes it again with message indexes, summary and footer, as ``mcap recover`` does. For a
rosbag2 bag directory each listed ``.mcap`` is repaired and ``metadata.yaml`` is rewritten
from what was recovered.

The input is never changed unless ``in_place=True``; then each file is written to a
temporary file beside it and renamed over it only once complete.
"""

import dataclasses
import os
from pathlib import Path
import tempfile
from typing import Dict, List, Optional, Tuple, Union

from mcap.records import (Attachment, Channel, Chunk, Footer, Header, Message, Metadata,
                          Schema)
from mcap.stream_reader import breakup_chunk, StreamReader
from mcap.writer import CompressionType, Writer
import yaml

from threat_planner.bag.cdr import canonical_cdr
from threat_planner.bag.metadata import (bag_information, file_entry, topic_entry,
                                         write_bag_metadata)
from threat_planner.errors import RecordingError

__all__ = ['RepairReport', 'repair_recording']

PathLike = Union[str, os.PathLike]
_MAGIC = b'\x89MCAP0\r\n'
_SUFFIX = '.repaired'


@dataclasses.dataclass
class RepairReport:
    """What a repair recovered.

    Attributes
    ----------
    source, target : Path
        The input and the file or bag directory written.
    messages : int
        Messages recovered.
    topics : dict[str, int]
        Messages recovered per topic.
    chunks : int
        Complete chunks read.
    bytes_read : int
        Bytes of the input up to the end of the last complete record [bytes].
    bytes_dropped : int
        Bytes after it, lost [bytes].
    complete : bool
        Whether the input already ended with a valid footer (nothing was lost).
    payloads_fixed : int
        CDR payloads cut to their exact length and zero-padded (``fix_cdr``).

    """

    source: Path
    target: Path
    messages: int = 0
    topics: Dict[str, int] = dataclasses.field(default_factory=dict)
    chunks: int = 0
    bytes_read: int = 0
    bytes_dropped: int = 0
    complete: bool = True
    payloads_fixed: int = 0

    def summary(self) -> str:
        """Return the one-line summary the command line prints."""
        state = 'was complete' if self.complete else f'dropped {self.bytes_dropped} bytes'
        fixed = f', {self.payloads_fixed} CDR payloads fixed' if self.payloads_fixed else ''
        return (f'{self.source}: recovered {self.messages} messages on {len(self.topics)} '
                f'topics from {self.chunks} chunks, read {self.bytes_read} bytes, {state}'
                f'{fixed} -> {self.target}')

    def add(self, other: 'RepairReport') -> None:
        """Accumulate the counts of one file of a bag directory."""
        self.messages += other.messages
        for topic, n in other.topics.items():
            self.topics[topic] = self.topics.get(topic, 0) + n
        self.chunks += other.chunks
        self.bytes_read += other.bytes_read
        self.bytes_dropped += other.bytes_dropped
        self.complete = self.complete and other.complete
        self.payloads_fixed += other.payloads_fixed


@dataclasses.dataclass
class _Recovered:
    """Channel facts a bag's metadata.yaml needs, gathered while copying one file."""

    channels: Dict[int, Channel] = dataclasses.field(default_factory=dict)
    schemas: Dict[int, Schema] = dataclasses.field(default_factory=dict)
    counts: Dict[int, int] = dataclasses.field(default_factory=dict)
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None


def _one_line(exc: BaseException) -> str:
    text = ' '.join(str(exc).split()) or type(exc).__name__
    return f'{type(exc).__name__}: {text[:160]}'


def _records(stream):
    """Yield ``(record, end offset)`` of the complete top-level records, then stop."""
    reader = StreamReader(stream, emit_chunks=True, validate_crcs=True)
    records = reader.records
    while True:
        try:
            record = next(records)
        except StopIteration:
            return
        except Exception:  # noqa: B902 - the cut-off or corrupt tail fails in many ways
            return
        yield record, stream.tell()


def _copy(source: Path, target: Path, fix_cdr: bool) -> Tuple[RepairReport, _Recovered]:
    report = RepairReport(source=source, target=target)
    found = _Recovered()
    try:
        stream = open(source, 'rb')
    except OSError as exc:
        raise RecordingError(f'{source}: cannot open ({exc.strerror or exc})') from exc
    with stream:
        size = os.fstat(stream.fileno()).st_size
        if stream.read(len(_MAGIC)) != _MAGIC:
            raise RecordingError(f'{source}: not an MCAP file (bad magic)')
        stream.seek(0)
        records = _records(stream)
        first = next(records, None)
        if first is None or not isinstance(first[0], Header):
            raise RecordingError(f'{source}: not an MCAP file (no complete header record)')
        header, report.bytes_read = first
        try:
            out = open(target, 'wb')
        except OSError as exc:
            raise RecordingError(f'{target}: cannot create ({exc.strerror or exc})') from exc
        with out:
            writer = Writer(out, compression=CompressionType.ZSTD)
            writer.start(profile=header.profile, library=header.library)
            ids: Dict[int, int] = {0: 0}
            channel_ids: Dict[int, int] = {}
            report.complete = False
            for record, end in records:
                if isinstance(record, Chunk):
                    try:
                        inner = breakup_chunk(record, validate_crc=True)
                    except Exception:  # noqa: B902 - a corrupt chunk ends what is usable
                        break
                    report.chunks += 1
                else:
                    inner = [record]
                for item in inner:
                    _write(writer, item, ids, channel_ids, found, report, fix_cdr)
                report.bytes_read = end
                if isinstance(record, Footer):
                    # Complete only with the closing magic right after the footer.
                    stream.seek(end)
                    if stream.read() == _MAGIC:
                        report.complete, report.bytes_read = True, size
                    break
            writer.finish()
    report.bytes_dropped = size - report.bytes_read
    return report, found


def _write(writer: Writer, record, ids: Dict[int, int], channel_ids: Dict[int, int],
           found: _Recovered, report: RepairReport, fix_cdr: bool) -> None:
    # Schemas and channels recur in the summary section; the first occurrence counts.
    if isinstance(record, Schema) and record.id not in ids:
        ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
        found.schemas[record.id] = record
    elif isinstance(record, Channel) and record.id not in channel_ids:
        channel_ids[record.id] = writer.register_channel(
            record.topic, record.message_encoding, ids.get(record.schema_id, 0),
            dict(record.metadata))
        found.channels[record.id] = record
        found.counts[record.id] = 0
    elif isinstance(record, Message) and record.channel_id in channel_ids:
        data = record.data
        channel = found.channels[record.channel_id]
        schema = found.schemas.get(channel.schema_id)
        if fix_cdr and schema is not None and channel.message_encoding == 'cdr' \
                and schema.encoding == 'ros2msg':
            try:
                fixed = canonical_cdr(data, schema.name, schema.data.decode('utf-8'))
            except (RecordingError, UnicodeDecodeError):
                fixed = data  # not walkable: keep it as it was
            report.payloads_fixed += fixed != data
            data = fixed
        writer.add_message(channel_ids[record.channel_id], record.log_time, data,
                           record.publish_time, record.sequence)
        found.counts[record.channel_id] += 1
        report.messages += 1
        report.topics[channel.topic] = report.topics.get(channel.topic, 0) + 1
        found.start_ns = record.log_time if found.start_ns is None else min(
            found.start_ns, record.log_time)
        found.end_ns = record.log_time if found.end_ns is None else max(
            found.end_ns, record.log_time)
    elif isinstance(record, Metadata):
        writer.add_metadata(record.name, dict(record.metadata))
    elif isinstance(record, Attachment):
        writer.add_attachment(record.create_time, record.log_time, record.name,
                              record.media_type, record.data)
    # Indexes, statistics, DataEnd and the footer are left out: the writer rebuilds them.


def _replace_atomically(tmp: Path, target: Path) -> None:
    try:
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise RecordingError(f'{target}: cannot replace ({exc.strerror or exc})') from exc


def _repair_file(source: Path, target: Path, in_place: bool,
                 fix_cdr: bool) -> Tuple[RepairReport, _Recovered]:
    if not in_place:
        return _copy(source, target, fix_cdr)
    fd, name = tempfile.mkstemp(prefix=f'.{source.name}.', suffix='.tmp', dir=source.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        report, found = _copy(source, tmp, fix_cdr)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _replace_atomically(tmp, source)
    report.target = source
    return report, found


def _metadata(old: dict, files: List[Tuple[str, _Recovered]]) -> dict:
    """Return rosbag2's v9 bag information for the recovered files."""
    topics: Dict[str, dict] = {}
    entries = []
    for name, found in files:
        for cid, channel in found.channels.items():
            schema = found.schemas.get(channel.schema_id)
            try:
                qos = yaml.safe_load(channel.metadata.get('offered_qos_profiles', '')) or []
            except yaml.YAMLError:
                qos = []
            entry = topics.setdefault(channel.topic, topic_entry(
                channel.topic, schema.name if schema is not None else '',
                channel.message_encoding, qos, channel.metadata.get('topic_type_hash', ''), 0))
            entry['message_count'] += found.counts[cid]
        entries.append(file_entry(name, found.start_ns, found.end_ns,
                                  sum(found.counts.values())))
    return bag_information(topics.values(), entries, base=old)


def _bag_files(bag: Path) -> Tuple[dict, List[str]]:
    meta = bag / 'metadata.yaml'
    old: dict = {}
    names: List[str] = []
    if meta.is_file():
        try:
            old = yaml.safe_load(meta.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
            names = [Path(n).name for n in old['relative_file_paths']]
        except (OSError, yaml.YAMLError, KeyError, TypeError):
            # A metadata.yaml cut off mid-write is as repairable as the files.
            old, names = {}, []
    if not names:
        names = sorted(p.name for p in bag.glob('*.mcap'))
    if not names:
        raise RecordingError(f'{bag}: directory holds no .mcap file')
    return (old if isinstance(old, dict) else {}), names


def _repair_bag(bag: Path, target: Optional[Path], in_place: bool,
                fix_cdr: bool) -> RepairReport:
    old, names = _bag_files(bag)
    out_dir = bag if in_place else (target or bag.with_name(bag.name + _SUFFIX))
    if not in_place:
        if out_dir.resolve() == bag.resolve():
            raise RecordingError(f'{out_dir}: is the input bag; use in_place to rewrite it')
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise RecordingError(f'{out_dir}: cannot create ({exc.strerror or exc})') from exc
    total = RepairReport(source=bag, target=out_dir)
    files = []
    for name in names:
        report, found = _repair_file(bag / name, out_dir / name, in_place, fix_cdr)
        total.add(report)
        files.append((name, found))
    write_bag_metadata(out_dir, _metadata(old, files))
    return total


def default_target(source: PathLike) -> Path:
    """Return where a repair writes by default: ``x.mcap`` -> ``x.repaired.mcap``.

    Parameters
    ----------
    source : str or os.PathLike
        A ``.mcap`` file or a bag directory (``bag`` -> ``bag.repaired``).

    Returns
    -------
    Path
        The default output path.

    """
    source = Path(source)
    if source.is_dir():
        return source.with_name(source.name + _SUFFIX)
    stem = source.name[:-5] if source.name.lower().endswith('.mcap') else source.name
    return source.with_name(stem + _SUFFIX + '.mcap')


def repair_recording(source: PathLike, target: Optional[PathLike] = None, *,
                     in_place: bool = False, fix_cdr: bool = False) -> RepairReport:
    """Rewrite what is readable of a damaged MCAP file or rosbag2 bag as a complete one.

    Parameters
    ----------
    source : str or os.PathLike
        A ``.mcap`` file, or a rosbag2 bag directory (its ``metadata.yaml`` lists the
        files; the ``.mcap`` files in it are taken when that is missing or cut off).
    target : str or os.PathLike, optional
        Output file or directory; :func:`default_target` if omitted. Not allowed with
        ``in_place``.
    in_place : bool
        Replace the input: each file is written to a temporary file beside it, then
        renamed over it.
    fix_cdr : bool
        Also cut ``cdr`` payloads of ``ros2msg`` channels to their exact length and zero
        their padding (:func:`threat_planner.bag.cdr.canonical_cdr`), so that bags written
        by rclpy's serialiser open in ``rosbags``.

    Returns
    -------
    RepairReport
        Messages recovered, bytes read and dropped, where it was written.

    Raises
    ------
    RecordingError
        If the input is missing or not MCAP, the output would overwrite the input
        without ``in_place``, or a file cannot be written.

    """
    source = Path(source)
    if in_place and target is not None:
        raise RecordingError(f'{target}: an output path cannot be given with in_place')
    if not source.exists():
        raise RecordingError(f'{source}: no such file or directory')
    if source.is_dir():
        return _repair_bag(source, None if target is None else Path(target), in_place,
                           fix_cdr)
    out = source if in_place else Path(target) if target is not None else \
        default_target(source)
    if not in_place:
        if out.exists() and out.resolve() == source.resolve():
            raise RecordingError(f'{out}: is the input file; use in_place to rewrite it')
        if out.is_dir():
            out = out / source.name
        out.parent.mkdir(parents=True, exist_ok=True)
    return _repair_file(source, out, in_place, fix_cdr)[0]
