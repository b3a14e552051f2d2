"""The recorder on a full disk: every I/O failure is a RecordingError, reported once.

A 64 KiB tmpfs stands in for the full disk (root mounts it; the tests skip with the
reason where mounting is not allowed). Three phases: the disk is full before the recorder
opens (file and folder mode), it fills up while recording (file and folder mode), and
``close()`` after the failure neither raises the error again nor loses what was written
before: the tolerant reader reads it back.
"""

import contextlib
import os
from pathlib import Path
import subprocess

from geometry_msgs.msg import PoseStamped
import pytest

from threat_planner.bag import McapRecorder, read_messages
from threat_planner.errors import RecordingError

T0 = 1_700_000_000_000_000_000  # [ns]


@contextlib.contextmanager
def small_disk(tmp_path: Path, size: str = '64k'):
    """Mount a tmpfs of `size` at tmp_path/disk for the block; skip where not allowed."""
    mount = tmp_path / 'disk'
    mount.mkdir()
    done = subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={size}', 'tmpfs', str(mount)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs (needs root): {done.stderr.strip()}')
    try:
        yield mount
    finally:
        subprocess.run(['umount', '-l', str(mount)], check=False)


def fill(disk: Path) -> None:
    """Fill `disk` to the last byte."""
    with open(disk / 'filler', 'wb', buffering=0) as f:
        with contextlib.suppress(OSError):
            while True:
                f.write(b'\0' * 4096)
                os.fsync(f.fileno())
    with contextlib.suppress(OSError):
        (disk / 'filler.more').write_bytes(b'\0' * 512)


def pose(i: int) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = 'map'
    msg.pose.position.x = float(i)
    msg.pose.orientation.w = 1.0
    return msg


@pytest.mark.parametrize('name', ['out.mcap', 'bags'])
def test_opening_on_a_full_disk_is_a_recording_error(tmp_path, name):
    with small_disk(tmp_path) as disk:
        fill(disk)
        with pytest.raises(RecordingError, match='cannot create recording') as info:
            McapRecorder(disk / name, flush_interval_s=None)
        assert '\n' not in str(info.value)
        assert 'No space left on device' in str(info.value)


@pytest.mark.parametrize('name', ['out.mcap', 'bags'])
def test_filling_up_while_recording_stops_once_and_keeps_what_was_written(tmp_path, name):
    with small_disk(tmp_path) as disk:
        rec = McapRecorder(disk / name, chunk_size=2048, flush_interval_s=None)
        written, errors = 0, []
        for i in range(5000):
            try:
                rec.write('/pose', pose(i), log_time_ns=T0 + i)
            except RecordingError as exc:
                errors.append(str(exc))
                if len(errors) == 3:
                    break
                continue
            written += 1
            if i % 10 == 9:
                try:
                    rec.flush()
                except RecordingError as exc:
                    errors.append(str(exc))
        assert errors, 'the disk never filled: make it smaller'
        assert 'No space left on device' in errors[0]
        # After the first failure every call says the recording stopped, and why.
        assert all('recording stopped after' in e for e in errors[1:])
        assert rec.failed is not None
        rec.close()  # must not raise the same error again
        rec.close()
        assert rec.closed
        back = list(read_messages(rec.path, tolerant=True))
        assert 0 < len(back) <= written
        assert [m[2] for m in back] == [T0 + i for i in range(len(back))]
        if rec.bag_dir is not None:
            assert (rec.bag_dir / 'metadata.yaml').is_file()


def test_close_on_a_full_disk_raises_once(tmp_path):
    with small_disk(tmp_path, '96k') as disk:
        rec = McapRecorder(disk / 'out.mcap', chunk_size=1 << 20, flush_interval_s=None)
        for i in range(20):
            rec.write('/pose', pose(i), log_time_ns=T0 + i)
        fill(disk)
        # The chunk and summary written by close() do not fit.
        with pytest.raises(RecordingError, match='cannot finish recording'):
            for i in range(2000):
                rec.write('/pose', pose(i), log_time_ns=T0 + 20 + i)
            rec.close()
        rec.close()
        assert rec.closed
