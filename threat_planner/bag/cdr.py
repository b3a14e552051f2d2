"""Exact, deterministic CDR payloads: trim and zero what rclpy leaves behind.

``rclpy.serialization.serialize_message`` (Fast CDR, Jazzy) writes a correct CDR body but
returns a buffer sized by an upper bound, so some types carry trailing bytes past the
payload (``rcl_interfaces/msg/ParameterEvent``: 8 of 96 for one parameter), and it never
writes the alignment padding, so those bytes are whatever the heap held. ``rosbags``
rejects the trailing bytes ("CDR message size mismatch") and the padding leaks memory into
files and makes two recordings of one message differ.

:func:`canonical_cdr` walks the payload guided by the ``ros2msg`` definition (the full
concatenated text the recorder stores as schema), finds where it ends and which bytes are
padding, and returns the payload cut to its exact length with every padding byte zero.
The walk reads only lengths: a run of fixed-size elements (``geometry_msgs/Point[]``,
``float32[]``, ``uint8[]``) is skipped in one step, so the cost is proportional to the
number of strings and variable-size elements, not to the payload size.

Alignment follows classic CDR (XCDR1) as ROS 2 writes it: a primitive of n bytes starts at
a multiple of n (at most 8) counted from the end of the 4-byte encapsulation header;
sequence and string lengths are uint32; an empty array aligns nothing.
"""

import dataclasses
import functools
import re
import struct
from typing import Dict, List, Optional, Tuple

from threat_planner.bag.definitions import message_definition, message_type_name
from threat_planner.errors import RecordingError

__all__ = ['CdrLayout', 'canonical_cdr', 'parse_definition', 'serialize_cdr']

_SIZES = {'bool': 1, 'byte': 1, 'char': 1, 'int8': 1, 'uint8': 1, 'int16': 2, 'uint16': 2,
          'int32': 4, 'uint32': 4, 'float32': 4, 'int64': 8, 'uint64': 8, 'float64': 8}
_STRINGS = ('string', 'wstring')
_SEPARATOR = re.compile(r'^={80}\s*$', re.MULTILINE)
_FIELD = re.compile(
    r'^(?P<base>[A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*){0,2})'
    r'(?:<=\d+)?(?:\[(?P<bound><=)?(?P<n>\d*)\])?'
    r'\s+(?P<name>[A-Za-z][A-Za-z0-9_]*)\s*(?P<rest>.*)$')
_TYPE = re.compile(r'^([A-Za-z][A-Za-z0-9_]*)/(?:msg/)?([A-Za-z][A-Za-z0-9_]*)$')
# Encapsulation kinds of classic CDR: big and little endian (plain and parameter list).
_ENDIAN = {b'\x00\x00': '>', b'\x00\x01': '<', b'\x00\x02': '>', b'\x00\x03': '<'}


@dataclasses.dataclass(frozen=True)
class Field:
    """One field of a message type.

    Parameters
    ----------
    name : str
        Field name.
    base : str
        Primitive name (``float64``, ``string``) or ``pkg/msg/Type``.
    count : int or None
        ``None`` for a single value, ``-1`` for a sequence (``[]`` or ``[<=N]``),
        else the length of a fixed array.

    """

    name: str
    base: str
    count: Optional[int] = None


def _canonical(name: str, package: str) -> str:
    if '/' not in name:
        return 'std_msgs/msg/Header' if name == 'Header' else f'{package}/msg/{name}'
    match = _TYPE.match(name)
    if match is None:
        raise RecordingError(f'field type {name!r} is not of the form pkg/msg/Type')
    return f'{match.group(1)}/msg/{match.group(2)}'


def _parse_block(text: str, package: str) -> Tuple[Field, ...]:
    fields = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        match = _FIELD.match(line)
        if match is None:
            raise RecordingError(f'definition line {line!r} is not "type name"')
        if match.group('rest').startswith('='):
            continue  # a constant: not part of the payload
        base = match.group('base')
        if base not in _SIZES and base not in _STRINGS:
            base = _canonical(base, package)
        n = match.group('n')
        count = None if match.group('n') is None else (
            -1 if (match.group('bound') or n == '') else int(n))
        fields.append(Field(match.group('name'), base, count))
    if not fields:
        # rosidl gives an empty message this one member so the struct is not empty.
        fields.append(Field('structure_needs_at_least_one_member', 'uint8'))
    return tuple(fields)


def parse_definition(definition: str, type_name: str) -> Dict[str, Tuple[Field, ...]]:
    """Parse a concatenated ``ros2msg`` definition into the fields of every type in it.

    Parameters
    ----------
    definition : str
        The root type's ``.msg`` text, then blocks ``MSG: pkg/Type`` behind 80 ``=``.
    type_name : str
        ``pkg/msg/Type`` (or ``pkg/Type``) of the root.

    Returns
    -------
    dict[str, tuple of Field]
        ``{'pkg/msg/Type': fields}``, the root included.

    Raises
    ------
    RecordingError
        If a line or a block header does not parse.

    """
    root = _canonical(type_name, '')
    blocks = _SEPARATOR.split(definition)
    types = {root: _parse_block(blocks[0], root.split('/')[0])}
    for block in blocks[1:]:
        header, _, body = block.lstrip('\n').partition('\n')
        if not header.startswith('MSG: '):
            raise RecordingError(f'definition block of {root} starts with {header!r}, '
                                 'not "MSG: pkg/Type"')
        name = _canonical(header[5:].strip(), '')
        types.setdefault(name, _parse_block(body, name.split('/')[0]))
    return types


class _Walk:
    """State of one walk over a payload: the bytes, their end, the padding found."""

    __slots__ = ('data', 'n', 'u32', 'pads', 'runs')

    def __init__(self, data: bytes, endian: str):
        self.data = data
        self.n = len(data)
        self.u32 = struct.Struct(endian + 'I').unpack_from
        self.pads: List[Tuple[int, int]] = []
        # Padding repeated in a run of identical fixed-size elements:
        # (first element start, element size, element count, pads relative to the start).
        self.runs: List[Tuple[int, int, int, Tuple[Tuple[int, int], ...]]] = []

    def align(self, pos: int, size: int) -> int:
        new = pos + (-(pos - 4)) % size
        if new != pos:
            self.pads.append((pos, new))
        return new

    def length(self, pos: int, what: str) -> Tuple[int, int]:
        pos = self.align(pos, 4)
        if pos + 4 > self.n:
            raise RecordingError(f'CDR payload ends at byte {self.n} inside the length of '
                                 f'{what}')
        return self.u32(self.data, pos)[0], pos + 4


class CdrLayout:
    """The walk of one message type, compiled from its definition.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` of the root.
    definition : str
        Its full concatenated ``ros2msg`` text.

    Raises
    ------
    RecordingError
        If the definition does not parse, misses a type it uses, or uses ``wstring``
        (which neither mcap_ros2 nor rosbags decodes).

    """

    def __init__(self, type_name: str, definition: str):
        self.type_name = _canonical(type_name, '')
        self._types = parse_definition(definition, self.type_name)
        # Per fixed-size type and start offset mod 8: (size, padding relative to start).
        self._fixed: Dict[str, Optional[List[Tuple[int, Tuple[Tuple[int, int], ...]]]]] = {}
        for name in self._types:
            self._fixed_layout(name, ())

    def _fields(self, name: str) -> Tuple[Field, ...]:
        fields = self._types.get(name)
        if fields is None:
            raise RecordingError(f'definition of {self.type_name} lacks the type {name}')
        return fields

    def _fixed_layout(self, name: str, stack: tuple):
        """Return the layouts by start offset mod 8 of a fixed-size type, else None."""
        if name in self._fixed:
            return self._fixed[name]
        if name in stack:
            raise RecordingError(f'definition of {self.type_name} is recursive at {name}')
        fixed = True
        for f in self._fields(name):
            if f.base == 'wstring':
                raise RecordingError(f'{name} field {f.name} is a wstring, which no MCAP '
                                     'reader decodes')
            if f.count == -1 or f.base == 'string' or (
                    f.base not in _SIZES and self._fixed_layout(f.base, stack + (name,))
                    is None):
                fixed = False
        layouts = None
        if fixed:
            layouts = []
            for start in range(8):
                walk = _Walk(b'', '<')
                end = self._walk_fields(walk, name, 4 + start)
                pads = tuple((a - 4 - start, b - 4 - start) for a, b in walk.pads)
                layouts.append((end - 4 - start, pads))
        self._fixed[name] = layouts
        return layouts

    def _walk_fields(self, walk: _Walk, name: str, pos: int) -> int:
        for f in self._fields(name):
            if f.count is None:
                pos = self._walk_one(walk, f.base, pos, f.name)
            else:
                count = f.count
                if count == -1:
                    count, pos = walk.length(pos, f'{name}.{f.name}')
                    if count > walk.n - pos:
                        # Every element takes at least one byte.
                        raise RecordingError(
                            f'CDR payload of {self.type_name}: {name}.{f.name} claims '
                            f'{count} elements, only {walk.n - pos} bytes left')
                pos = self._walk_many(walk, f.base, pos, count, f'{name}.{f.name}')
        return pos

    def _walk_one(self, walk: _Walk, base: str, pos: int, what: str) -> int:
        size = _SIZES.get(base)
        if size is not None:
            return walk.align(pos, size) + size
        if base == 'string':
            length, pos = walk.length(pos, what)
            if length > walk.n - pos:
                raise RecordingError(f'CDR payload of {self.type_name}: string {what} claims '
                                     f'{length} bytes, only {walk.n - pos} left')
            return pos + length
        layouts = self._fixed.get(base)
        if layouts is not None:
            size, pads = layouts[(pos - 4) % 8]
            walk.pads.extend((pos + a, pos + b) for a, b in pads)
            return pos + size
        return self._walk_fields(walk, base, pos)

    def _walk_many(self, walk: _Walk, base: str, pos: int, count: int, what: str) -> int:
        if count == 0:
            return pos
        size = _SIZES.get(base)
        if size is not None:
            return walk.align(pos, size) + size * count
        layouts = self._fixed.get(base)
        if layouts is None:
            for _ in range(count):
                pos = self._walk_one(walk, base, pos, what)
            return pos
        while count:
            size, pads = layouts[(pos - 4) % 8]
            if (pos - 4 + size) % 8 == (pos - 4) % 8:
                # Every further element starts at the same offset mod 8: same layout.
                if pads:
                    walk.runs.append((pos, size, count, pads))
                return pos + size * count
            walk.pads.extend((pos + a, pos + b) for a, b in pads)
            pos += size
            count -= 1
        return pos

    def extent(self, data: bytes) -> Tuple[int, List[Tuple[int, int]], list]:
        """Walk a payload; return its end, its padding ranges and repeated padding runs.

        Parameters
        ----------
        data : bytes
            A CDR payload with its 4-byte encapsulation header.

        Returns
        -------
        end : int
            Exact length of the payload [bytes].
        pads : list of (int, int)
            Padding byte ranges ``[start, stop)``.
        runs : list
            ``(start, element size, count, relative pads)`` of padded fixed-size runs.

        Raises
        ------
        RecordingError
            If the header is not classic CDR or the payload is shorter than its content.

        """
        endian = _ENDIAN.get(bytes(data[:2]))
        if endian is None or len(data) < 4:
            raise RecordingError(f'CDR payload of {self.type_name} has no CDR header '
                                 f'(first bytes {bytes(data[:4]).hex()})')
        walk = _Walk(data, endian)
        end = self._walk_fields(walk, self.type_name, 4)
        if end > walk.n:
            raise RecordingError(f'CDR payload of {self.type_name} is {walk.n} bytes, its '
                                 f'content needs {end}')
        return end, walk.pads, walk.runs

    def canonical(self, data: bytes) -> bytes:
        """Return ``data`` cut to its exact length, with zero padding and header options.

        Parameters
        ----------
        data : bytes
            A CDR payload of this type.

        Returns
        -------
        bytes
            The same message, deterministic byte for byte.

        """
        end, pads, runs = self.extent(data)
        out = bytearray(memoryview(data)[:end])
        out[2:4] = b'\0\0'  # options: XCDR1 carries no padding count
        for a, b in pads:
            out[a:b] = bytes(b - a)
        for start, size, count, rel in runs:
            for a, b in rel:
                for k in range(a, b):
                    out[start + k:start + k + size * (count - 1) + 1:size] = bytes(count)
        return bytes(out)


@functools.lru_cache(maxsize=256)
def _layout(type_name: str, definition: str) -> CdrLayout:
    return CdrLayout(type_name, definition)


def canonical_cdr(data: bytes, type_name: str, definition: str) -> bytes:
    """Return a CDR payload cut to its exact length with every padding byte zero.

    Parameters
    ----------
    data : bytes
        CDR payload (4-byte header included), e.g. from ``serialize_message``.
    type_name : str
        ``pkg/msg/Type`` of the payload.
    definition : str
        The type's full concatenated ``ros2msg`` definition.

    Returns
    -------
    bytes
        The canonical payload: decodes as before, nothing after its last field.

    Raises
    ------
    RecordingError
        If the definition does not parse or the payload is shorter than its content.

    """
    return _layout(type_name, definition).canonical(data)


def serialize_cdr(msg, topic: str = '') -> bytes:
    """Serialise an rclpy message to its exact CDR payload (no trailing bytes, padding 0).

    rclpy's buffer has trailing bytes and uninitialised padding (see bag/cdr.py); what this
    returns is what the recorder writes and what a publisher may send as raw bytes.

    Raises
    ------
    RecordingError
        Naming `topic`, if the message cannot be serialised.

    """
    from rclpy.serialization import serialize_message
    where = f'{topic}: ' if topic else ''
    try:
        data = serialize_message(msg)
    except Exception as exc:  # noqa: B902 - rclpy's C layer raises assorted types
        raise RecordingError(f'{where}cannot serialise {type(msg).__name__}: {exc}') from exc
    type_name = message_type_name(msg)
    try:
        return canonical_cdr(data, type_name, message_definition(type_name))
    except RecordingError as exc:
        raise RecordingError(f'{where}{exc}') from exc
