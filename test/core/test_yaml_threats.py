"""The fast threats-list reader gives exactly what PyYAML gives, on any text."""

from pathlib import Path

from hypothesis import given, settings, strategies as st
import pytest
import yaml

from threat_planner.core.inputs import yaml_threats
from threat_planner.core.inputs.scenario import load_scenario, save_scenario

DATA = Path(__file__).resolve().parents[1] / 'data'
LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def _pyyaml(text: str):
    """PyYAML's document, or the exception type it raises."""
    try:
        return repr(yaml.load(text, Loader=LOADER))
    except yaml.YAMLError as exc:
        return type(exc)


def _fast(text: str):
    """The fast reader's document (repr tells 1 from 1.0), or the exception type."""
    try:
        return repr(yaml_threats.load_document(text))
    except yaml.YAMLError as exc:
        return type(exc)


@pytest.mark.parametrize('name', sorted(p.name for p in DATA.glob('*.yaml')))
def test_bundled_scenarios_read_the_same_and_their_threat_lists_take_the_fast_way(name):
    text = (DATA / name).read_text()
    assert _fast(text) == _pyyaml(text)
    if yaml.safe_load(text).get('threats'):
        assert yaml_threats._fast_threats(text) is not None


def test_saved_scenarios_take_the_fast_way_and_load_back_bit_for_bit(tmp_path):
    scenario = load_scenario(DATA / 'big300_0.yaml')
    save_scenario(scenario, tmp_path / 's.yaml')
    text = (tmp_path / 's.yaml').read_text()
    assert yaml_threats._fast_threats(text) is not None
    back = load_scenario(tmp_path / 's.yaml')
    assert back.threats.positions.tobytes() == scenario.threats.positions.tobytes()
    assert back.threats.intensities.tobytes() == scenario.threats.intensities.tobytes()


PLAIN = st.one_of(st.integers(-10**6, 10**6).map(str),
                  # YAML floats need a dot: repr gives 1e+16 and 5e-324 without one.
                  st.floats(allow_nan=False, allow_infinity=False).map(repr).filter(
                      lambda t: '.' in t),
                  st.sampled_from(['0', '-0', '+5', '1.', '2.E-4', '1.5e+3', '0.0', '007.5']))
# Tokens YAML 1.1 reads otherwise than Python: octal, strings (1e5 and 1.5e3 lack a dot
# or an exponent sign), sexagesimal, underscores, specials, quotes, tags, comments.
ODD = st.sampled_from(['0777', '-012', '1e5', '1.5e3', '-.5', '.5', '.inf', '.nan', '1_000',
                       '0x1F', '0b101', '1:30', "'3.0'", '"4"', '~', 'null', 'yes', '3.0 # c',
                       '&a 1.0', '!!str 2', '[1]', ''])
# Lines and neighbours that a plain block does not have.
ODD_LINES = ['  lethal_radius: 2.0', '# note', '   intensity: 1.0', '- 7', '', '\t- 1']
HEADS = ['description: "x\nthreats:\n"\n', 'threats_file: t.npy\n', 'a: |\n  threats:\n',
         '%YAML 1.1\n---\n', 'threats: &t\n']
TAILS = ['"goal": 1\n', '...\n', 'threats: []\n', '  oops: 1\n', '# end\n', 'b: *t\n']


@st.composite
def documents(draw, odd: bool):
    """A scenario-like threats block in one of the shapes; with ``odd``, one oddity in it."""
    indent = draw(st.sampled_from(['', '  ', '    ']))
    deeper = draw(st.sampled_from(['', '  ']))
    pad = draw(st.sampled_from(['', ' ']))
    n = draw(st.integers(1, 4))
    tokens = [draw(PLAIN) for _ in range(5 * n)]
    where = draw(st.sampled_from(['token', 'line', 'head', 'tail'])) if odd else None
    if where == 'token':
        tokens[draw(st.integers(0, len(tokens) - 1))] = draw(ODD)
    lines = []
    for i in range(n):
        x, y, z, f, r = tokens[5 * i:5 * i + 5]
        radius = draw(st.booleans())
        shape = draw(st.sampled_from(['flow', 'inline', 'block']))
        if shape == 'flow':
            r = f', lethal_radius: {r}' if radius else ''
            lines.append(f'{indent}- {{position: [{x}, {y},{z}], intensity: {f}{r}}}{pad}')
        else:
            if shape == 'inline':
                lines.append(f'{indent}- position: [{x}, {y},{z}]{pad}')
            else:
                lines += [f'{indent}- position:{pad}'] + [
                    f'{indent}  {deeper}- {v}{pad}' for v in (x, y, z)]
            lines.append(f'{indent}  intensity: {f}{pad}')
            if radius:
                lines.append(f'{indent}  lethal_radius: {r}')
    if where == 'line':
        lines.insert(draw(st.integers(0, len(lines))), indent + draw(st.sampled_from(ODD_LINES)))
    head = draw(st.sampled_from(HEADS)) if where == 'head' else 'name: a\n'
    tail = draw(st.sampled_from(TAILS)) if where == 'tail' else 'goal: [1, 2, 3]\n'
    return head + 'threats:\n' + '\n'.join(lines) + '\n' + tail


@settings(max_examples=300, deadline=None)
@given(documents(odd=False))
def test_plain_blocks_take_the_fast_way_and_read_as_pyyaml_reads_them(text):
    assert yaml_threats._fast_threats(text) is not None
    assert _fast(text) == _pyyaml(text)


@settings(max_examples=600, deadline=None)
@given(documents(odd=True))
def test_blocks_with_any_oddity_read_exactly_as_pyyaml_reads_them(text):
    assert _fast(text) == _pyyaml(text)


def test_a_threats_header_inside_a_quoted_string_is_not_taken_for_the_key():
    text = ('description: "one\nthreats:\n- position: [1.0, 2.0, 3.0]\n  intensity: 5.0\n"\n'
            'threats: []\n')
    assert _fast(text) == _pyyaml(text)
    assert yaml.safe_load(text)['threats'] == []


@pytest.mark.parametrize('encode', [lambda t: t.encode(), lambda t: b'\xef\xbb\xbf' + t.encode(),
                                    lambda t: t.encode('utf-16')])
def test_bytes_with_or_without_a_byte_order_mark_read_as_pyyaml_reads_them(encode):
    data = encode((DATA / 'uniform20_0.yaml').read_text())
    assert repr(yaml_threats.load_document(data)) == repr(yaml.load(data, Loader=LOADER))
