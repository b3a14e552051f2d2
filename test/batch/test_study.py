"""Study files: what they sweep, and every mistake found before any plan runs."""

from dataclasses import replace
import shutil

from hypothesis import given, settings, strategies as st
import pytest
from study_harness import cli, write_study

from threat_planner.batch.study import load_study, study_from_dict
from threat_planner.batch.tasks import chunks, task_list
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.settings import PLANNER_SETTINGS
from threat_planner.errors import InputError


def test_a_study_sweeps_the_product_relative_to_its_own_folder(tmp_path, monkeypatch):
    path = write_study(tmp_path / 's', w=[0.2, 0.5, 0.8], method=['best', 'paper'],
                       settings={'max_climb_deg': [20, 30], 'n_points': 30},
                       uncertainty={'samples': 4, 'position_sigma_m': 5.0},
                       robust={'samples': 3})
    monkeypatch.chdir(tmp_path)           # globs are relative to the study, not the cwd
    study = load_study(path)
    assert [s.key for s in study.scenarios] == ['fields/uniform20_0.yaml',
                                                'fields/weak20_0.yaml']
    assert study.w == (0.2, 0.5, 0.8) and study.methods == ('best', 'paper')
    assert study.settings == (('max_climb_deg', (20.0, 30.0)), ('n_points', (30,)))
    assert study.sampling.samples == 4 and study.sampling.robust_samples == 3
    assert study.sampling.intensity_sigma == 0.0 and study.sampling.seed == 0
    tasks = task_list(study)
    assert len(tasks) == 2 * 3 * 2 * 2 * 1 * 2
    assert len({t.key for t in tasks}) == len(tasks)
    assert [t.index for t in tasks] == list(range(len(tasks)))
    first = tasks[0]
    assert (first.scenario, first.w, first.method, first.plan) == \
        ('fields/uniform20_0.yaml', 0.2, 'best', 'nominal')
    assert first.config == PlannerConfig(w=0.2, method='best', max_climb_deg=20.0,
                                         n_points=30)
    # Every task lands in exactly one chunk, in order.
    assert [t for c in chunks(tasks, 2) for t in c] == tasks


def test_defaults_when_w_method_and_settings_are_left_out(tmp_path):
    study = load_study(write_study(tmp_path, scenarios=('weak20_0',)))
    assert study.w == (PlannerConfig().w,) and study.methods == (PlannerConfig().method,)
    assert study.settings == () and study.sampling is None and study.plans == ('nominal',)


def test_task_keys_survive_a_move_and_follow_the_scenario_bytes(tmp_path):
    a = write_study(tmp_path / 'a', w=[0.3, 0.6])
    keys = [t.key for t in task_list(load_study(a))]
    shutil.copytree(tmp_path / 'a', tmp_path / 'b')
    assert [t.key for t in task_list(load_study(tmp_path / 'b' / 'study.yaml'))] == keys
    weak = tmp_path / 'b' / 'fields' / 'weak20_0.yaml'
    weak.write_text(weak.read_text().replace('intensity: 16471.3', 'intensity: 16471.4'))
    moved = task_list(load_study(tmp_path / 'b' / 'study.yaml'))
    changed = {t.scenario for t, k in zip(moved, keys) if t.key != k}
    assert changed == {'fields/weak20_0.yaml'}


def test_seeds_are_shared_by_a_scenarios_plans_and_differ_between_scenarios(tmp_path):
    study = load_study(write_study(tmp_path, w=[0.3, 0.6],
                                   uncertainty={'samples': 2, 'seed': 7},
                                   robust={'samples': 2}))
    tasks = task_list(study)
    by_scenario = {}
    for t in tasks:
        by_scenario.setdefault(t.scenario, set()).add(tuple(t.evaluation_seed))
        assert t.evaluation_seed != t.robust_seed and t.evaluation_seed[0] == 7
    assert all(len(s) == 1 for s in by_scenario.values())
    assert len(set.union(*by_scenario.values())) == 2


GOOD = {'scenarios': ['fields/*.yaml'], 'w': [0.5], 'method': 'best',
        'settings': {'max_climb_deg': [20, 30]},
        'uncertainty': {'samples': 4, 'position_sigma_m': 5.0}, 'robust': {'samples': 2}}


@pytest.mark.parametrize('change,needle', [
    ({'wz': [0.5]}, 'unknown field "wz"; did you mean "w"?'),
    ({'scenarios': ['nothere/*.yaml']}, 'scenarios[0]: "nothere/*.yaml" matches no file'),
    ({'scenarios': []}, 'scenarios: empty list'),
    ({'scenarios': None}, 'scenarios: must be a glob or a list of globs'),
    ({'w': []}, 'w: empty sweep'),
    ({'method': []}, 'method: empty sweep'),
    ({'settings': {'max_climb_deg': []}}, 'settings.max_climb_deg: empty sweep'),
    ({'w': [0.5, 1.5]}, 'w[1]: must satisfy 0 < w < 1, got 1.5'),
    ({'w': [0.5, 0.5]}, 'w[1]: 0.5 is in the sweep twice'),
    ({'method': 'magic'}, 'method: must be one of paper, improved, best'),
    ({'settings': {'max_clim_deg': 20}},
     'settings.max_clim_deg: not a plan setting; did you mean "max_climb_deg"?'),
    ({'settings': {'n_points': 2.5}}, 'settings.n_points: must be an integer >= 2'),
    ({'settings': {'max_climb_deg': [20, 95]}}, 'settings.max_climb_deg[1]: must be finite'),
    ({'settings': {'w': 0.4}}, 'settings.w: sweep w with the top-level key "w"'),
    ({'settings': [1, 2]}, 'settings: must be a mapping'),
    ({'uncertainty': None}, 'robust: needs an uncertainty block'),
    ({'uncertainty': {'samples': 0}}, 'uncertainty.samples: must be an integer >= 1, got 0'),
    ({'uncertainty': {'sigma': 1}}, 'unknown field "uncertainty.sigma"'),
    ({'uncertainty': {'position_sigma_m': -1}},
     'uncertainty.position_sigma_m: must be a finite number >= 0, got -1'),
    ({'robust': {'samples': 1.5}}, 'robust.samples: must be an integer >= 1, got 1.5'),
    ({'robust': 16}, 'robust: must be a mapping with the keys samples'),
])
def test_each_mistake_is_one_line_naming_the_field(tmp_path, change, needle):
    write_study(tmp_path)
    data = {**GOOD, **change}
    data = {k: v for k, v in data.items() if v is not None or k == 'scenarios'}
    with pytest.raises(InputError) as err:
        study_from_dict(data, tmp_path / 'study.yaml')
    message = str(err.value)
    assert needle in message and '\n' not in message
    assert message.startswith(str((tmp_path / 'study.yaml').resolve()))


def test_a_bad_scenario_in_a_glob_is_named(tmp_path):
    write_study(tmp_path)
    bad = tmp_path / 'fields' / 'zz_bad.yaml'
    bad.write_text((tmp_path / 'fields' / 'weak20_0.yaml').read_text()
                   .replace('intensity: 16471.3', 'intensity: -1'))
    with pytest.raises(InputError, match='zz_bad.yaml.*intensity'):
        study_from_dict(GOOD, tmp_path / 'study.yaml')


def test_the_command_line_refuses_before_any_work(tmp_path):
    path = write_study(tmp_path, w=[0.5, 0.5])
    out = tmp_path / 'out'
    p = cli('batch', path, '--out', out)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and 'w[1]: 0.5 is in the sweep twice' in lines[0]
    assert not out.exists()
    path.write_text('scenarios: [fields/*.yaml]\nw: [0.5\n')
    p = cli('batch', path, '--out', out)
    assert p.returncode == 2 and 'not valid YAML at line' in p.stderr
    assert 'Traceback' not in p.stderr and not out.exists()


SWEPT = sorted(n for n, s in PLANNER_SETTINGS.items()
               if s.kind in (int, float) and n not in ('w',))


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(SWEPT),
       value=st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                       st.integers(-10, 20_000)))
def test_a_study_takes_a_setting_exactly_when_plannerconfig_does(tmp_path_factory, name,
                                                                 value):
    """The study's rule for a setting is the planner's own (the CLI's)."""
    folder = tmp_path_factory.mktemp('s')
    write_study(folder, scenarios=('weak20_0',))
    try:
        replace(PlannerConfig(), **{name: value}).validated()
        planner_ok = True
    except InputError:
        planner_ok = False
    try:
        study = study_from_dict({'scenarios': 'fields/*.yaml', 'settings': {name: value}},
                                folder / 'study.yaml')
        study_ok = True
    except InputError as exc:
        assert f'settings.{name}: {PLANNER_SETTINGS[name].rule}' in str(exc)
        study_ok = False
    assert study_ok == planner_ok
    if study_ok:
        assert task_list(study)[0].config == replace(PlannerConfig(), **{name: value})
