"""rosbag2's ``metadata.yaml`` (version 9) for a bag folder: built and written in one place.

Used by the recorder (rewritten at every flush, so a killed bag stays playable with counts
up to the last flush) and by ``threat-planner bag repair`` (rewritten for what was
recovered).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterable, Mapping, Optional

import yaml

from threat_planner.errors import RecordingError

__all__ = ['METADATA_VERSION', 'bag_information', 'file_entry', 'io_reason', 'topic_entry',
           'write_bag_metadata']

METADATA_VERSION = 9


def io_reason(exc: BaseException) -> str:
    """Return the one-line reason of an I/O error, without the file name repeated."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc)


def topic_entry(name: str, type_name: str, encoding: str, qos_profiles: list,
                type_hash: str, count: int) -> dict:
    """Return one ``topics_with_message_count`` entry."""
    return {'topic_metadata': {'name': name, 'type': type_name,
                               'serialization_format': encoding,
                               'offered_qos_profiles': qos_profiles,
                               'type_description_hash': type_hash},
            'message_count': count}


def file_entry(path: str, start_ns: Optional[int], end_ns: Optional[int], count: int) -> dict:
    """Return one ``files`` entry: the file's first time and duration [ns] and count."""
    start = start_ns or 0
    return {'path': path, 'starting_time': {'nanoseconds_since_epoch': start},
            'duration': {'nanoseconds': (end_ns - start) if count and end_ns else 0},
            'message_count': count}


def bag_information(topics: Iterable[dict], files: list[dict],
                    base: Optional[Mapping] = None) -> dict:
    """Return the ``rosbag2_bagfile_information`` of a bag of these files and topics.

    Parameters
    ----------
    topics : iterable of dict
        :func:`topic_entry` s.
    files : list of dict
        :func:`file_entry` s, one per ``.mcap`` file.
    base : Mapping, optional
        An existing bag's information whose other keys are kept (repair).

    """
    starts = [f['starting_time']['nanoseconds_since_epoch'] for f in files
              if f['message_count']]
    ends = [f['starting_time']['nanoseconds_since_epoch'] + f['duration']['nanoseconds']
            for f in files if f['message_count']]
    start = min(starts) if starts else 0
    info = dict(base or {})
    info.update({
        'version': info.get('version', METADATA_VERSION),
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': (max(ends) - start) if ends else 0},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': sum(f['message_count'] for f in files),
        'topics_with_message_count': list(topics),
        # Chunk compression is internal to MCAP; rosbag2 leaves these empty for it.
        'compression_format': info.get('compression_format', ''),
        'compression_mode': info.get('compression_mode', ''),
        'relative_file_paths': [f['path'] for f in files],
        'files': files,
    })
    info.setdefault('custom_data', None)
    info.setdefault('ros_distro', os.environ.get('ROS_DISTRO', 'jazzy'))
    return info


def write_bag_metadata(bag_dir: Path, info: Mapping) -> None:
    """Write ``bag_dir/metadata.yaml`` atomically (a temporary file, then a rename).

    Raises
    ------
    RecordingError
        If it cannot be written; no temporary file is left behind.

    """
    text = yaml.safe_dump({'rosbag2_bagfile_information': dict(info)}, sort_keys=False,
                          default_flow_style=False)
    target = Path(bag_dir) / 'metadata.yaml'
    tmp = target.with_suffix('.yaml.tmp')
    try:
        tmp.write_text(text, encoding='utf-8')
        os.replace(tmp, target)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise RecordingError(f'{target}: cannot write bag metadata: {io_reason(exc)}') \
            from exc
