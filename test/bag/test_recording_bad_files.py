"""Tests of the bag reader on bad files: truncated, corrupt, not MCAP, missing, unknown."""

from mcap.reader import make_reader
from mcap.writer import Writer
import pytest

from bag_samples import check_path, make_path, T0
from threat_planner.bag import McapRecorder, read_messages, read_ros_messages
from threat_planner.errors import RecordingError


# -- bad files -------------------------------------------------------------------------


def _multi_chunk_file(path, n=40):
    with McapRecorder(path, flush_interval_s=None) as rec:
        for i in range(n):
            rec.write('/planned_path', make_path(), log_time_ns=T0 + i)
            if i % 5 == 4:
                rec.flush()
    return n


def _assert_error_names_file(excinfo, path):
    text = str(excinfo.value)
    assert str(path) in text and '\n' not in text


def test_truncated_file_strict_raises_tolerant_reads_complete_chunks(tmp_path):
    out = tmp_path / 'cut.mcap'
    n = _multi_chunk_file(out)
    with open(out, 'rb') as f:
        chunk = make_reader(f).get_summary().chunk_indexes[5]
    # Cut inside the sixth chunk, as a kill in the middle of writing it would.
    out.write_bytes(out.read_bytes()[:chunk.chunk_start_offset + chunk.chunk_length // 2])
    with pytest.raises(RecordingError) as excinfo:
        list(read_messages(out))
    _assert_error_names_file(excinfo, out)
    with pytest.raises(RecordingError):
        list(read_ros_messages(out))
    got = list(read_messages(out, tolerant=True))
    assert len(got) == 25 < n  # the five complete chunks
    assert [m.log_time_ns for m in got] == [T0 + i for i in range(len(got))]
    for m in got:
        check_path(m.msg)
    assert len(list(read_ros_messages(out, tolerant=True))) == len(got)


def test_corrupt_chunk_raises(tmp_path):
    out = tmp_path / 'corrupt.mcap'
    _multi_chunk_file(out)
    with open(out, 'rb') as f:
        chunk = make_reader(f).get_summary().chunk_indexes[1]
    data = bytearray(out.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 16] = bytes(b ^ 0xFF for b in data[middle:middle + 16])
    out.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match='corrupt') as excinfo:
        list(read_messages(out))
    _assert_error_names_file(excinfo, out)
    # The tolerant reader keeps the intact first chunk and stops at the damage.
    assert len(list(read_messages(out, tolerant=True))) == 5


@pytest.mark.parametrize('content', [b'', b'not an mcap file at all\n' * 20,
                                     b'\x89MCAP0\r\n'])
@pytest.mark.parametrize('tolerant', [False, True])
def test_non_mcap_file_raises(tmp_path, content, tolerant):
    out = tmp_path / 'junk.mcap'
    out.write_bytes(content)
    with pytest.raises(RecordingError) as excinfo:
        list(read_messages(out, tolerant=tolerant))
    _assert_error_names_file(excinfo, out)


def test_missing_file_raises(tmp_path):
    with pytest.raises(RecordingError) as excinfo:
        list(read_messages(tmp_path / 'absent.mcap'))
    _assert_error_names_file(excinfo, tmp_path / 'absent.mcap')


@pytest.mark.parametrize('tolerant', [False, True])
def test_unknown_schema_encoding_raises(tmp_path, tolerant):
    out = tmp_path / 'proto.mcap'
    with open(out, 'wb') as f:
        writer = Writer(f)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('foo_msgs/msg/Bar', 'protobuf', b'\x0a\x03Bar')
        channel = writer.register_channel('/bar', 'cdr', schema)
        writer.add_message(channel, log_time=1, data=b'\x00\x01\x00\x00', publish_time=1)
        writer.finish()
    with pytest.raises(RecordingError, match='protobuf') as excinfo:
        list(read_messages(out, tolerant=tolerant))
    _assert_error_names_file(excinfo, out)
