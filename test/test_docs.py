"""The README and docs/ agree with the code: the node's interface, links, paths, suites."""

import glob
import importlib.util
from pathlib import Path
import re

import pytest

from threat_planner.core.inputs.settings import NODE_SETTINGS
from threat_planner.ros.interface import INPUT_TOPICS, OUTPUT_TOPICS
from threat_planner.ros.plan_service import PLAN_SERVICE, QUEUE_BOUND

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
DOCS = ROOT / 'docs'
PAGES = ('method.md', 'node.md', 'bags.md', 'benchmarks.md', 'flight.md', 'detection.md')
README_LINES = 200
INTERFACE_HEADING = '## Interface of the node'

_TYPES = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
# Backticked paths whose first folder is one of these are checked to exist; they may be
# written from the repository root or from threat_planner/ and its layers.
_PATH_ROOTS = ('threat_planner', 'core', 'ros', 'bag', 'cli', 'bench', 'test', 'docs',
               'config', 'examples', 'launch', 'rviz', 'foxglove', 'world', 'inputs',
               'cost', 'network', 'optimise', 'methods', 'recording', 'conversions', '.ci')
_PATH_BASES = ('', 'threat_planner', 'threat_planner/core', 'threat_planner/ros',
               'threat_planner/bag')
_PATH = re.compile(r'`([.\w*-]+(?:/[\w.*-]+)+\.(?:py|md|yaml|json|txt|mcap|png|npy|rviz))`')
_RESULT_FILE = re.compile(r'`([\w*-]+\.(?:md|txt|json|png))`')
# Files that benchmarks.md names which are not in bench/results/ (the shared scenarios').
_NOT_RESULTS = {'README.md', 'reference.json', 'reference_box.json'}
_SUITE = re.compile(r'\bsuite[ \n]`([a-z_]+)|`python -m bench[ \n]([a-z_]+)')
_LINK = re.compile(r'\]\(([^)\s]+)\)')


def _pages():
    return [README] + [DOCS / name for name in PAGES]


def _slug(heading):
    """GitHub's anchor of a heading."""
    text = heading.strip().lower()
    text = re.sub(r'[^\w\- ]', '', text)
    return text.replace(' ', '-')


def _anchors(path):
    return {_slug(line.lstrip('#')) for line in path.read_text().splitlines()
            if line.startswith('#')}


def _interval(s):
    """The range of a numeric setting as the README writes it: (0, 1], 2..10000."""
    if s.kind is int:
        return f'{int(s.lo)}..{int(s.hi)}'
    lo = '(-inf' if s.lo is None else ('(' if s.lo_open else '[') + f'{s.lo:g}'
    hi = 'inf)' if s.hi is None else f'{s.hi:g}' + (')' if s.hi_open else ']')
    return f'{lo}, {hi}'


def _default(value):
    """A default as config/planner.yaml writes it."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return value if value else "''"
    if isinstance(value, list):
        return '[' + ', '.join(repr(float(v)) for v in value) + ']'
    return repr(value)


def expected_parameter_row(s):
    """The type and the 'default and range' cell of a node parameter's README row."""
    kind = _TYPES.get(s.kind, f'double[{s.length}]')
    if s.choices is not None:
        span = ', '.join(s.choices)
    elif s.kind in (int, float):
        span = _interval(s)
    else:
        span = ''
    return kind, f'`{_default(s.default)}`' + (f'; {span}' if span else '')


def _qos(profile):
    words = [profile.reliability.name, profile.durability.name]
    return ', '.join(w.lower().replace('_', ' ') for w in words) + f', depth {profile.depth}'


def _message_type(name):
    return name.replace('/msg/', '/')


def interface_rows(text):
    """Rows of the README's interface table: name -> (kind, type, cell, what)."""
    section = text.split(INTERFACE_HEADING, 1)[1].split('\n## ', 1)[0]
    rows = {}
    for line in section.splitlines():
        if not line.startswith('| `'):
            continue
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        name = cells[0].strip('`')
        key = (name, cells[1])
        assert key not in rows, f'{name} ({cells[1]}) listed twice'
        rows[key] = tuple(cells[1:])
    return rows


def interface_problems(text):
    """What the README's interface table gets wrong about the node; [] if nothing."""
    rows = interface_rows(text)
    problems = []
    want = {}
    for kind, topics in (('topic in', INPUT_TOPICS), ('topic out', OUTPUT_TOPICS)):
        for name, (type_name, qos) in topics.items():
            want[(name, kind)] = (_message_type(type_name), _qos(qos))
    want[(PLAN_SERVICE, 'service')] = ('nav_msgs/srv/GetPlan', None)
    for name, s in NODE_SETTINGS.items():
        want[(name, 'parameter')] = expected_parameter_row(s)
    for key in sorted(set(rows) - set(want)):
        problems.append(f'{key[0]} ({key[1]}) is not in the node\'s interface')
    for key, (type_name, cell) in want.items():
        if key not in rows:
            problems.append(f'{key[0]} ({key[1]}) is missing')
            continue
        _, got_type, got_cell, _ = rows[key]
        if got_type != type_name:
            problems.append(f'{key[0]}: type {got_type!r}, the code says {type_name!r}')
        if key[1] == 'service':
            if str(QUEUE_BOUND) not in got_cell:
                problems.append(f'{key[0]}: the queue bound is {QUEUE_BOUND}')
        elif got_cell != cell:
            problems.append(f'{key[0]}: {got_cell!r}, the code says {cell!r}')
    order = [name for name, kind in rows if kind == 'parameter']
    if sorted(order) == sorted(NODE_SETTINGS) and order != list(NODE_SETTINGS):
        problems.append('parameters are not in the order of settings.py')
    return problems


def test_readme_is_a_front_door():
    text = README.read_text()
    assert len(text.splitlines()) <= README_LINES
    # CI runs .ci/run, which runs the README's test command.
    assert 'make test' in text and 'make demo' in text
    assert 'make test' in (ROOT / '.ci' / 'run').read_text()
    for name in PAGES:
        assert f'docs/{name}' in text, f'README does not link docs/{name}'


def test_interface_table_lists_every_topic_service_and_parameter():
    assert interface_problems(README.read_text()) == []


def test_interface_check_catches_a_stale_table():
    text = README.read_text()
    base = set(interface_problems(text))
    first = next(iter(NODE_SETTINGS.values()))
    kind, cell = expected_parameter_row(first)
    row = f'| `{first.name}` | parameter | {kind} | {cell} |'
    assert row in text

    def new_problems(changed):
        return set(interface_problems(changed)) - base

    assert new_problems(text.replace(row, row.replace(cell, '`-1`')))
    renamed = new_problems(text.replace('| `plan_info` | topic out', '| `info` | topic out'))
    assert renamed == {'info (topic out) is not in the node\'s interface',
                       'plan_info (topic out) is missing'}
    removed = '\n'.join(line for line in text.splitlines()
                        if not line.startswith('| `record` | parameter'))
    assert new_problems(removed) == {'record (parameter) is missing'}


@pytest.mark.parametrize('page', _pages(), ids=lambda p: p.name)
def test_links_resolve(page):
    for target in _LINK.findall(page.read_text()):
        if re.match(r'[a-z]+:', target):
            continue
        path, _, anchor = target.partition('#')
        file = (page.parent / path).resolve() if path else page
        assert file.exists(), f'{page.name}: link to {target}: no such file'
        if anchor and file.suffix == '.md':
            assert anchor in _anchors(file), f'{page.name}: no heading #{anchor} in {path}'


@pytest.mark.parametrize('page', _pages(), ids=lambda p: p.name)
def test_named_paths_exist(page):
    for token in _PATH.findall(page.read_text()):
        if token.split('/')[0] not in _PATH_ROOTS:
            continue
        found = any(glob.glob(str(ROOT / base / token)) for base in _PATH_BASES)
        assert found, f'{page.name} names {token}, which does not exist'


def test_benchmarks_name_existing_results():
    text = (DOCS / 'benchmarks.md').read_text()
    results = ROOT / 'bench' / 'results'
    for name in set(_RESULT_FILE.findall(text)) - _NOT_RESULTS:
        assert glob.glob(str(results / name)), f'bench/results/{name} does not exist'


def test_docs_name_existing_suites():
    entry_file = ROOT / 'bench' / '__main__.py'
    if not entry_file.exists():
        pytest.skip('no python -m bench entry point in this checkout')
    spec = importlib.util.spec_from_file_location('bench_entry', entry_file)
    entry = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(entry)
    named = {a or b for page in _pages() for a, b in _SUITE.findall(page.read_text())}
    assert named, 'the docs name no suite'
    unknown = named - set(entry.SUITES)
    assert not unknown, f'not suites of python -m bench: {sorted(unknown)}'
