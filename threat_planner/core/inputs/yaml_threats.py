"""Fast exact reading of a scenario YAML's ``threats`` list.

libyaml parses in C, but PyYAML resolves and constructs every scalar in Python: a
10,000-threat scenario (80,000 scalars) took 0.75 s to load, three Delaunays of the same
points. :func:`load_document` reads the ``threats`` block with one regular expression
instead, when the block has the plain shape that :func:`~.scenario.save_scenario` and
most hand-written files use, and gives the document to PyYAML without it. Anything else
(comments, quotes, anchors, other keys, numbers that YAML 1.1 reads differently from
Python) goes to PyYAML whole, so the result is always the one PyYAML gives.
"""

import re

import yaml

__all__ = ['load_document']

# Only tokens that YAML 1.1 and Python read as the same number: YAML's int (no leading
# zero: 0777 is octal there) and its float (a dot, and a signed exponent: 1e5 and
# 1.5e3 are strings there).
_INT = r'[-+]?(?:0|[1-9][0-9]*)'
_FLOAT = r'[-+]?[0-9]+\.[0-9]*(?:[eE][-+][0-9]+)?'
_NUM = rf'({_FLOAT}|{_INT})'
_HEADER = re.compile(r'^threats:[ ]*\n', re.MULTILINE)
_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def _item_pattern(indent: str) -> re.Pattern:
    """One threat at sequence indent ``indent``: position, intensity, lethal radius.

    As a block mapping (position in flow or block style) or as a one-line flow mapping.
    """
    item, key, end = re.escape(indent) + '- ', re.escape(indent) + '  ', r' *(?:\n|\Z)'
    xyz = rf'\[ *{_NUM} *, *{_NUM} *, *{_NUM} *\]'
    # The three block entries share one indent, at or right of the key's, as YAML demands.
    entries = (rf' *\n(?P<e>{key} *)- {_NUM} *\n'
               rf'(?P=e)- {_NUM} *\n(?P=e)- {_NUM} *\n')
    block = (rf'position:(?: {xyz} *\n|{entries}){key}intensity: {_NUM}{end}'
             rf'(?:{key}lethal_radius: {_NUM}{end})?')
    flow = (rf'\{{ *position: {xyz} *, *intensity: {_NUM} *'
            rf'(?:, *lethal_radius: {_NUM} *)?\}}{end}')
    return re.compile(rf'{item}(?:{block}|{flow})')


def _number(token: str) -> int | float:
    """Return the value PyYAML constructs for a token that matched ``_NUM``."""
    return float(token) if '.' in token else int(token)


def _fast_threats(text: str) -> tuple[str, list, int] | None:
    """Split off a plain ``threats`` block.

    Returns (the rest with ``threats: []`` in its place, the list, that line's number).

    None when the block is not plain or is not the only top-level ``threats`` key.
    """
    headers = list(_HEADER.finditer(text))
    if len(headers) != 1:
        return None
    begin, pos = headers[0].start(), headers[0].end()
    first = text[pos:text.find('\n', pos) + 1 or len(text)]
    indent = first[:len(first) - len(first.lstrip(' '))]
    if not first.startswith(indent + '- '):
        return None
    pattern = _item_pattern(indent)
    skip = pattern.groupindex['e'] - 1
    threats = []
    while True:
        m = pattern.match(text, pos)
        if m is None:
            break
        # The numbers of whichever form matched, in order: x y z F and maybe the radius.
        v = [_number(t) for i, t in enumerate(m.groups()) if t is not None and i != skip]
        threat = {'position': v[:3], 'intensity': v[3]}
        if len(v) == 5:
            threat['lethal_radius'] = v[4]
        threats.append(threat)
        pos = m.end()
    # The block must end at the end of the text or at the next top-level plain key.
    if not threats or (pos < len(text) and not re.match(r'[A-Za-z_]', text[pos])):
        return None
    return text[:begin] + 'threats: []\n' + text[pos:], threats, text.count('\n', 0, begin)


def load_document(text: str | bytes) -> object:
    """Parse a scenario document as PyYAML's safe loader would.

    Args:
        text: The YAML text.

    Returns:
        The parsed document; a plain ``threats`` block is read without PyYAML.

    Raises:
        yaml.YAMLError: as PyYAML raises it on the whole text.
    """
    if isinstance(text, bytes):
        try:
            text = text.decode('utf-8')
        except UnicodeDecodeError:
            return yaml.load(text, Loader=_LOADER)
    split = _fast_threats(text) if '\r' not in text else None
    if split is not None:
        rest, threats, line = split
        loader = _LOADER(rest)
        try:
            node = loader.get_single_node()
            # The header could sit in a quoted string: use the split only if PyYAML's
            # top-level "threats" key is the line that replaced the block.
            # A later duplicate key wins in PyYAML: there must be just the one.
            keys = [k for k, _ in node.value] if isinstance(node, yaml.MappingNode) else []
            keys = [k for k in keys if k.value == 'threats']
            if (len(keys) == 1 and keys[0].start_mark.line == line
                    and keys[0].start_mark.column == 0):
                data = loader.construct_document(node)
                if isinstance(data, dict) and data.get('threats') == []:
                    data['threats'] = threats
                    return data
        except yaml.YAMLError:
            pass
        finally:
            loader.dispose()
    return yaml.load(text, Loader=_LOADER)
