"""Scenario key ``threats_file``: a compact .npy or .csv table of x y z F next to the YAML."""

from pathlib import Path

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
import yaml

from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.errors import ScenarioError

DATA = Path(__file__).resolve().parents[1] / 'data'


def _split(tmp_path: Path, rows: np.ndarray, suffix: str, header: bool = True) -> Path:
    """Write uniform20_0's YAML without its threats, and the rows as threats_file."""
    doc = yaml.safe_load((DATA / 'uniform20_0.yaml').read_text())
    doc.pop('threats')
    doc['threats_file'] = f'threats{suffix}'
    table = tmp_path / f'threats{suffix}'
    if suffix == '.npy':
        np.save(table, rows)
    else:
        np.savetxt(table, rows, delimiter=',', fmt='%.17g', header='x,y,z,F' if header else '',
                   comments='')
    path = tmp_path / 'split.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize('suffix, header', [('.npy', False), ('.csv', True), ('.csv', False)])
def test_threats_file_gives_the_same_scenario_as_the_inline_list(tmp_path, suffix, header):
    inline = load_scenario(DATA / 'uniform20_0.yaml')
    rows = np.column_stack([inline.threats.positions, inline.threats.intensities])
    split = load_scenario(_split(tmp_path, rows, suffix, header))
    assert np.array_equal(split.threats.positions, inline.threats.positions)
    assert np.array_equal(split.threats.intensities, inline.threats.intensities)
    assert np.array_equal(split.start, inline.start) and split.name == inline.name


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(*[st.floats(0.0, 100.0)] * 3, st.floats(1.0, 1e7)),
                min_size=0, max_size=30))
def test_csv_round_trip_is_exact(tmp_path_factory, rows):
    tmp = tmp_path_factory.mktemp('rt')
    table = np.array(rows, float).reshape(-1, 4)
    sc = load_scenario(_split(tmp, table, '.csv'))
    assert np.array_equal(sc.threats.positions, table[:, :3])
    assert np.array_equal(sc.threats.intensities, table[:, 3])


@pytest.mark.parametrize('content, expected', [
    ('x,y,z,F\n1,2,3\n', r'threats_file: threats.csv needs 4 numeric columns|not a table'),
    ('1,2,3,oops\n', r'threats_file: threats.csv is not a table of numbers'),
    ('1,2,3,-5\n', r'threats\[0\].intensity: must be > 0, got -5.0'),
    ('1,2,nan,5\n', r'threats.position\[0\]: not finite'),
])
def test_bad_tables_name_the_field(tmp_path, content, expected):
    path = _split(tmp_path, np.zeros((1, 4)) + 1.0, '.csv')
    (tmp_path / 'threats.csv').write_text(content)
    with pytest.raises(ScenarioError, match=expected) as info:
        load_scenario(path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and '\n' not in msg and 'np.' not in msg


def test_missing_wrong_suffix_and_both_given(tmp_path):
    path = _split(tmp_path, np.ones((2, 4)), '.npy')
    (tmp_path / 'threats.npy').unlink()
    with pytest.raises(ScenarioError, match='threats_file: cannot read'):
        load_scenario(path)
    doc = yaml.safe_load(path.read_text())
    for value, expected in (('threats.txt', 'threats.txt must end in .npy or .csv'),
                            (3, 'expected a file name, got 3')):
        doc['threats_file'] = value
        path.write_text(yaml.safe_dump(doc))
        with pytest.raises(ScenarioError, match=f'threats_file: {expected}'):
            load_scenario(path)
    doc['threats_file'] = 'threats.npy'
    doc['threats'] = [{'position': [1, 2, 3], 'intensity': 1.0}]
    path.write_text(yaml.safe_dump(doc))
    np.save(tmp_path / 'threats.npy', np.ones((2, 4)))
    with pytest.raises(ScenarioError, match='"threats" or "threats_file", not both'):
        load_scenario(path)


def test_npy_of_the_wrong_shape_is_refused(tmp_path):
    path = _split(tmp_path, np.ones((5, 3)), '.npy')
    with pytest.raises(ScenarioError, match=r'needs 4 numeric columns x y z F, got shape \[5'):
        load_scenario(path)


def test_cli_plans_a_split_scenario_and_reports_a_missing_table_in_one_line(tmp_path):
    import subprocess
    import sys
    inline = load_scenario(DATA / 'uniform20_0.yaml')
    rows = np.column_stack([inline.threats.positions, inline.threats.intensities])
    path = _split(tmp_path, rows, '.npy')
    cmd = [sys.executable, '-m', 'threat_planner.cli', 'plan', str(path), '--method', 'paper']
    ok = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0 and 'threats=20' in ok.stdout
    (tmp_path / 'threats.npy').unlink()
    bad = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.count('\n') == 1
    assert 'threats_file: cannot read' in bad.stderr and 'Traceback' not in bad.stderr


@pytest.mark.parametrize('threats_file', [None, 'big.npy', 'big.csv'])
def test_save_scenario_round_trip(tmp_path, threats_file):
    from threat_planner.core.inputs.scenario import save_scenario
    sc = load_scenario(DATA / 'clustered_0.yaml')
    save_scenario(sc, tmp_path / 'out.yaml', threats_file)
    back = load_scenario(tmp_path / 'out.yaml')
    assert np.array_equal(back.threats.positions, sc.threats.positions)
    assert np.array_equal(back.threats.intensities, sc.threats.intensities)
    assert np.array_equal(back.start, sc.start) and np.array_equal(back.box.hi, sc.box.hi)
    assert ('threats_file' in yaml.safe_load((tmp_path / 'out.yaml').read_text())) == bool(
        threats_file)


def test_save_scenario_refuses_a_bad_table_name(tmp_path):
    from threat_planner.core.inputs.scenario import save_scenario
    from threat_planner.errors import InputError
    with pytest.raises(InputError, match='threats_file: t.json must end in .npy or .csv'):
        save_scenario(load_scenario(DATA / 'weak20_0.yaml'), tmp_path / 'o.yaml', 't.json')
