"""Property-based tests (hypothesis) of scenario loading: junk in, only ScenarioError out.

Scenario-shaped dicts with absent, plausible or junk fields, and byte strings and YAML
texts with traps PyYAML's constructors reject: the loader raises nothing but a one-line
ScenarioError, and never hangs.
"""

import string

from hypothesis import example, given, settings, strategies as st
import yaml

from property_harness import _check_message, _FAST, CHEAP, fractions, time_limit
from threat_planner.core.inputs.scenario import load_scenario, scenario_from_dict
from threat_planner.errors import ScenarioError


# ---------------------------------------------------------------------------- scenarios

#: Scalars a YAML document may hold: None, bools, ints of any size, any float, strings.
junk_scalars = (st.none() | st.booleans() | st.integers()
                | st.sampled_from([10 ** 400, -10 ** 400]) | st.floats() | st.text(max_size=8))
junk = st.recursive(junk_scalars,
                    lambda inner: st.lists(inner, max_size=4)
                    | st.dictionaries(st.text(max_size=6), inner, max_size=4),
                    max_leaves=12)
numbers = st.floats(-10.0, 10.0) | st.integers(-10, 10)
#: A coordinate or intensity: usually a number, sometimes one junk scalar or junk value.
number_like = st.one_of(numbers, numbers, numbers, junk_scalars, junk)
point_like = st.one_of(st.lists(number_like, min_size=3, max_size=3),
                       st.lists(numbers, min_size=3, max_size=3), junk)
threat_like = st.one_of(
    st.fixed_dictionaries({'position': point_like, 'intensity': number_like}),
    st.fixed_dictionaries({}, optional={'position': point_like, 'intensity': number_like}),
    junk)


@st.composite
def scenario_dicts(draw):
    """Scenario-shaped dicts whose fields are each absent, plausible or junk."""
    fields = {
        'bounds': st.one_of(
            st.fixed_dictionaries({'min': point_like, 'max': point_like}),
            st.fixed_dictionaries({}, optional={'min': point_like, 'max': point_like}), junk),
        'start': point_like,
        'goal': point_like,
        'threats': st.lists(threat_like, max_size=3) | junk,
        'name': junk,
        'frame_id': junk,
        'description': junk,
    }
    out = {}
    for key, strategy in fields.items():
        if draw(st.integers(0, 9)):
            out[key] = draw(strategy)
    return out


@settings(max_examples=500, **_FAST)
@example({'bounds': {'min': [0, 0, 0], 'max': [10 ** 400, 1, 1]}, 'start': [0, 0, 0],
          'goal': [0, 0, 0], 'threats': []})
@example({'bounds': {'min': [0, 0, 0], 'max': [1, 1, 1]}, 'start': [0, 0, 0],
          'goal': [1, 1, 1], 'threats': [{'position': [0, 0, 0.5], 'intensity': -10 ** 400}]})
@given(scenario_dicts() | junk)
def test_scenario_from_dict_raises_only_scenario_error(data):
    try:
        with time_limit():
            scenario_from_dict(data, 'junk.yaml')
    except ScenarioError as exc:
        _check_message(exc)


def _mutate(text, where, what):
    i = int(where * len(text))
    return text[:i] + what + text[i:]


#: YAML that parses but that PyYAML's constructors reject with ValueError, or too deep.
YAML_TRAPS = ['a: 2001-13-14\n', 'start: !!float abc\n', 'x: !!int x\n', '{a: ' * 1000,
              'bounds: !!timestamp 2001-02-30\n', '\t- a\n', '*x\n']
yaml_texts = st.one_of(
    st.sampled_from(YAML_TRAPS),
    st.text(alphabet=string.printable, max_size=200),
    scenario_dicts().map(lambda d: yaml.safe_dump(d, allow_unicode=True)),
    st.builds(_mutate, scenario_dicts().map(lambda d: yaml.safe_dump(d)), fractions,
              st.sampled_from(YAML_TRAPS + [':', '- ', '"', '&a ', '\x00'])))


@CHEAP
@example(b'[' * 2000)
@example(b'\x80')
@given(st.binary(max_size=200) | yaml_texts.map(lambda t: t.encode('utf-8', 'replace')))
def test_load_scenario_raises_only_scenario_error(tmp_path_factory, blob):
    path = tmp_path_factory.getbasetemp() / 'junk.yaml'
    path.write_bytes(blob)
    try:
        with time_limit():
            load_scenario(path)
    except ScenarioError as exc:
        _check_message(exc)
