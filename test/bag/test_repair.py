"""Tests of threat_planner.bag.repair and ``threat-planner bag repair``.

A real multi-chunk recording is cut at byte offsets a crash can leave (right after the
header, inside a chunk, one byte short of a chunk's end, inside the record after a chunk,
inside the summary, in the footer); the repaired file must open in rosbags' AnyReader and
in mcap's strict indexed reader and hold exactly the messages of the complete chunks.
"""

from pathlib import Path
import subprocess
import sys

from mcap.reader import make_reader
from mcap.writer import Writer
import pytest
from rosbags.highlevel import AnyReader
import yaml

from threat_planner.bag import LATCHED_QOS, McapRecorder, read_messages, read_ros_messages
from threat_planner.bag.repair import default_target, repair_recording
from threat_planner.errors import RecordingError

from test_cdr import make_diagnostics, make_markers, make_parameter_event, make_path

REPO = Path(__file__).resolve().parents[2]
T0 = 1_700_000_000_000_000_007
MAKERS = [make_parameter_event, make_path, make_markers, make_diagnostics]


def record(target, n=40):
    """Record n messages with strictly increasing log times in chunks of about 5."""
    with McapRecorder(target, chunk_size=4000, flush_interval_s=None) as rec:
        rec.add_topic('/path', 'nav_msgs/msg/Path', LATCHED_QOS)
        for i in range(n):
            msg = MAKERS[i % len(MAKERS)]()
            rec.write(f'/{type(msg).__name__.lower()}', msg, log_time_ns=T0 + i)
    return rec.path


def strict_messages(path):
    """(topic, log time, payload) of every message, through mcap's indexed reader."""
    with open(path, 'rb') as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_summary() is not None
        return [(c.topic, m.log_time, bytes(m.data))
                for _, c, m in reader.iter_messages(log_time_order=False)]


def anyreader_count(path):
    with AnyReader([Path(path)]) as reader:
        n = 0
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            n += 1
    return n


@pytest.fixture(scope='module')
def full(tmp_path_factory):
    path = record(tmp_path_factory.mktemp('full') / 'full.mcap')
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 5
    return path, chunks, strict_messages(path)


def cut_points(chunks, size):
    k = len(chunks) // 2
    end = chunks[k].chunk_start_offset + chunks[k].chunk_length
    summary_start = chunks[-1].chunk_start_offset + chunks[-1].chunk_length
    return {
        'after header': chunks[0].chunk_start_offset,
        'mid-chunk': chunks[k].chunk_start_offset + chunks[k].chunk_length // 2,
        'chunk short by one byte': end - 1,
        'at a chunk end': end,
        'mid-record after a chunk': end + 5,
        'inside the summary': summary_start + (size - summary_start) // 2,
        'in the footer': size - 3,
        'complete': size,
    }


@pytest.mark.parametrize('where', ['after header', 'mid-chunk', 'chunk short by one byte',
                                   'at a chunk end', 'mid-record after a chunk',
                                   'inside the summary', 'in the footer', 'complete'])
def test_repaired_cut_file_opens_strictly_with_the_complete_chunks(full, tmp_path, where):
    path, chunks, messages = full
    data = path.read_bytes()
    at = cut_points(chunks, len(data))[where]
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:at])
    report = repair_recording(cut)
    out = tmp_path / 'cut.repaired.mcap'
    assert report.target == out and cut.read_bytes() == data[:at]
    # The complete chunks are those that end at or before the cut.
    last = max((c.message_end_time for c in chunks
                if c.chunk_start_offset + c.chunk_length <= at), default=None)
    expected = [m for m in messages if last is not None and m[1] <= last]
    assert strict_messages(out) == expected
    assert report.messages == len(expected) == anyreader_count(out)
    assert report.chunks == sum(c.chunk_start_offset + c.chunk_length <= at for c in chunks)
    assert report.bytes_read + report.bytes_dropped == at
    # A cut on a record boundary drops no byte but still loses the summary and footer.
    assert report.complete == (where == 'complete')
    assert (report.bytes_dropped == 0) == (where in ('complete', 'after header',
                                                     'at a chunk end'))
    # The library's own strict reader agrees, down to the rclpy messages.
    assert [m.log_time_ns for m in read_ros_messages(out)] == [m[1] for m in expected]


def test_metadata_attachments_schemas_and_header_are_preserved(tmp_path):
    src = tmp_path / 'meta.mcap'
    with open(src, 'wb') as f:
        w = Writer(f, chunk_size=200)
        w.start(profile='ros2', library='someone else 1.0')
        w.add_metadata('run', {'operator': 'x', 'site': 'y'})
        schema = w.register_schema('std_msgs/msg/String', 'ros2msg', b'string data\n')
        channel = w.register_channel('/s', 'cdr', schema, {'k': 'v'})
        for i in range(20):
            w.add_message(channel, log_time=i, publish_time=i, sequence=i,
                          data=b'\x00\x01\x00\x00\x02\x00\x00\x00a\x00')
        w.add_attachment(5, 6, 'notes.txt', 'text/plain', b'hello')
        w.finish()
    data = src.read_bytes()
    src.write_bytes(data[:len(data) - 60])  # the summary and footer lost
    report = repair_recording(src, tmp_path / 'out.mcap')
    assert report.messages == 20 and not report.complete
    with open(tmp_path / 'out.mcap', 'rb') as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_header().library == 'someone else 1.0'
        assert [(m.name, m.metadata) for m in reader.iter_metadata()] == [
            ('run', {'operator': 'x', 'site': 'y'})]
        assert [(a.name, a.data) for a in reader.iter_attachments()] == [
            ('notes.txt', b'hello')]
        (ch,) = reader.get_summary().channels.values()
        assert ch.metadata == {'k': 'v'}
        assert [m.sequence for _, _, m in reader.iter_messages()] == list(range(20))


def test_bag_directory_is_repaired_with_a_new_metadata_yaml(tmp_path):
    with McapRecorder(tmp_path / 'bags', chunk_size=4000, flush_interval_s=None) as rec:
        for i in range(30):
            rec.write('/path', make_path(), log_time_ns=T0 + i)
            rec.write('/event', make_parameter_event(), log_time_ns=T0 + i)
    bag, mcap = rec.bag_dir, rec.path
    mcap.write_bytes(mcap.read_bytes()[:mcap.stat().st_size // 3])
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information:\n  version: 9\n  sto')
    report = repair_recording(bag)
    out = default_target(bag)
    assert report.target == out == bag.with_name(bag.name + '.repaired')
    assert 0 < report.messages < 60
    info = yaml.safe_load((out / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['relative_file_paths'] == [mcap.name]
    assert info['message_count'] == report.messages == info['files'][0]['message_count']
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in info['topics_with_message_count']}
    assert counts == report.topics
    qos = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles'][0]
           for t in info['topics_with_message_count']}
    assert qos['/path']['reliability'] == 'reliable'
    with AnyReader([out]) as reader:  # rosbag2 directory: reads metadata.yaml
        assert reader.message_count == report.messages
        assert sum(1 for _ in reader.messages()) == report.messages
    assert len(list(read_messages(out))) == report.messages


def test_in_place_replaces_the_input_and_leaves_no_temporary_file(full, tmp_path):
    path, chunks, messages = full
    cut = tmp_path / 'run.mcap'
    cut.write_bytes(path.read_bytes()[:chunks[2].chunk_start_offset + 10])
    with pytest.raises(RecordingError, match='in_place'):
        repair_recording(cut, cut)
    report = repair_recording(cut, in_place=True)
    assert report.target == cut and [p.name for p in tmp_path.iterdir()] == ['run.mcap']
    assert strict_messages(cut) == [m for m in messages if m[1] <= chunks[1].message_end_time]


def test_old_bags_with_rclpy_padding_open_in_rosbags_after_fix_cdr(tmp_path):
    src = REPO / 'test/data/bags/uniform20.mcap'
    report = repair_recording(src, tmp_path / 'fixed.mcap', fix_cdr=True)
    assert report.complete and report.messages > 0
    assert anyreader_count(tmp_path / 'fixed.mcap') == report.messages
    # The fix changes bytes, never the messages.
    before = [m.msg for m in read_ros_messages(src)]
    assert [m.msg for m in read_ros_messages(tmp_path / 'fixed.mcap')] == before


def run_cli(*args):
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'bag', 'repair',
                           *map(str, args)], capture_output=True, text=True, cwd=REPO)


def test_cli_prints_one_summary_line(full, tmp_path):
    path, chunks, _ = full
    cut = tmp_path / 'c.mcap'
    cut.write_bytes(path.read_bytes()[:chunks[3].chunk_start_offset + 3])
    proc = run_cli(cut, tmp_path / 'o.mcap')
    assert proc.returncode == 0, proc.stderr
    (line,) = proc.stdout.splitlines()
    assert 'recovered' in line and 'dropped' in line and str(tmp_path / 'o.mcap') in line
    assert strict_messages(tmp_path / 'o.mcap')


@pytest.mark.parametrize('content', [b'', b'plain text, no mcap here\n', b'\x89MCAP0\r\n'])
def test_cli_refuses_non_mcap_with_one_line_and_exit_2(tmp_path, content):
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(content)
    proc = run_cli(bad)
    assert proc.returncode == 2 and proc.stdout == ''
    (line,) = proc.stderr.splitlines()
    assert 'not an MCAP file' in line and str(bad) in line
    assert [p.name for p in tmp_path.iterdir()] == ['bad.mcap']
    assert run_cli(bad, tmp_path / 'o.mcap', '--in-place').returncode == 2
