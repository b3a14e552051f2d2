"""One declaration per setting: PlannerConfig, node parameters, params file and CLI agree."""

from dataclasses import fields
from pathlib import Path

import pytest

from threat_planner.cli import build_parser
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.settings import (NODE_SETTINGS, params_file_text, PLANNER_SETTINGS,
                                                 SETTINGS)
from threat_planner.errors import InputError

ROOT = Path(__file__).resolve().parents[2]


def test_planner_config_fields_are_the_planner_settings():
    assert [f.name for f in fields(PlannerConfig)] == list(PLANNER_SETTINGS)
    defaults = PlannerConfig()
    for name, s in PLANNER_SETTINGS.items():
        assert getattr(defaults, name) == s.default, name


def test_every_setting_is_declared_once_with_help():
    names = [s.name for s in SETTINGS]
    assert len(names) == len(set(names))
    assert all(s.help and not s.help.endswith('.') for s in SETTINGS)


def test_params_file_is_generated_from_the_settings():
    """config/planner.yaml holds every node default with its help (regenerate on change:
    python -c 'from threat_planner.core.inputs.settings import params_file_text as t;
    print(t(), end="")'
    > config/planner.yaml)."""
    assert (ROOT / 'config' / 'planner.yaml').read_text() == params_file_text()


@pytest.mark.parametrize('setting', [s for s in SETTINGS if s.lo is not None],
                         ids=lambda s: s.name)
def test_validation_follows_the_declared_range(setting):
    s = setting
    if s.scope != 'planner':
        s.check(s.default)
        return
    if not s.lo_open:
        PlannerConfig(**{s.name: s.lo}).validated()
    below = s.lo - (1 if s.kind is int else (1e-9 if not s.lo_open else 0.0))
    with pytest.raises(InputError, match=f'^{s.name}: must'):
        PlannerConfig(**{s.name: below}).validated()
    if s.hi is not None:
        above = s.hi + (1 if s.kind is int else (0.0 if s.hi_open else 1e-6 * max(1, s.hi)))
        with pytest.raises(InputError, match=f'^{s.name}: must'):
            PlannerConfig(**{s.name: above}).validated()


def test_errors_print_plain_numbers():
    import numpy as np
    with pytest.raises(InputError, match=r'got -5\.0$'):
        PlannerConfig(w=np.float64(-5.0)).validated()


def test_cli_options_and_defaults_come_from_the_settings():
    text = build_parser()._subparsers._group_actions[0].choices['plan'].format_help()
    for s in PLANNER_SETTINGS.values():
        if s.cli is None:
            continue
        assert f'--{s.cli}' in text
        if s.kind is not bool:
            assert f'(default: {s.default})' in ' '.join(text.split())


def test_node_parameters_are_the_node_settings():
    pytest.importorskip('rclpy')
    from threat_planner.ros.parameters import descriptor, PARAMETER_DEFAULTS
    assert list(PARAMETER_DEFAULTS) == list(NODE_SETTINGS)
    for name, s in NODE_SETTINGS.items():
        d = descriptor(name)
        assert d.description == s.doc and d.additional_constraints == s.rule
        if s.kind is float and s.lo is not None and s.hi is not None:
            r = d.floating_point_range[0]
            assert (r.from_value, r.to_value) == (s.lo, s.hi)
        if s.kind is int and s.lo is not None and s.hi is not None:
            r = d.integer_range[0]
            assert (r.from_value, r.to_value) == (s.lo, s.hi)
