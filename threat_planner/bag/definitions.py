"""ROS 2 message types: names, full ``.msg`` definitions, classes and CDR decoding."""

import functools
import importlib
import importlib.metadata
import json
from pathlib import Path
import re
import sys
import threading
from typing import Callable, Dict, List, Optional


from threat_planner.errors import RecordingError

__all__ = ['MESSAGE_ENCODING', 'PROFILE', 'SCHEMA_ENCODING', 'canonical_type_name',
           'deserialize', 'get_message_class', 'message_definition', 'message_type_name',
           'msg_dependencies', 'type_description_hash']

PROFILE = 'ros2'
SCHEMA_ENCODING = 'ros2msg'
MESSAGE_ENCODING = 'cdr'
_SEPARATOR = '=' * 80
_PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))
_FIELD_TYPE = re.compile(r'[A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*){0,2}')
_TYPE_NAME = re.compile(r'^([A-Za-z][A-Za-z0-9_]*)/(?:msg/)?([A-Za-z][A-Za-z0-9_]*)$')


def _split_type(type_name: str):
    match = _TYPE_NAME.match(type_name or '')
    if match is None:
        raise RecordingError(
            f'message type {type_name!r} is not of the form pkg/msg/Type or pkg/Type')
    return match.group(1), match.group(2)


def canonical_type_name(type_name: str) -> str:
    """Return ``pkg/msg/Name`` for ``pkg/Name`` or ``pkg/msg/Name``."""
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
        text = load_text(canonical_type_name(name))
        result = text
        for dep in msg_dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                result += f'\n{_SEPARATOR}\nMSG: {dep}\n' + append(dep, depth - 1)
        return result

    return append(canonical_type_name(type_name), 50)


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
    key = canonical_type_name(type_name)
    with _DEFINITIONS_LOCK:
        if key not in _DEFINITIONS:
            _DEFINITIONS[key] = _build_definition(key, _load_msg_text)
        return _DEFINITIONS[key]


@functools.lru_cache(maxsize=None)
def type_description_hash(type_name: str) -> str:
    """Return the RIHS01 type hash rosbag2 records for a type (or '' if unknown)."""
    # rosidl installs <Type>.json next to <Type>.msg with the RIHS01 hash rosbag2 records;
    # an empty hash is what rosbag2 writes when it has none.
    path = _interface_file(type_name, '.json')
    if path is None:
        return ''
    try:
        entries = json.loads(path.read_text(encoding='utf-8')).get('type_hashes', [])
        return next((e['hash_string'] for e in entries
                     if e.get('type_name') == canonical_type_name(type_name)), '')
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
    canonical = canonical_type_name(type_name)
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
        raise RecordingError(
            f'bytes are not a valid {canonical_type_name(type_name)}: {exc}') from exc
