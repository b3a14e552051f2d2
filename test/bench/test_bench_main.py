"""``python -m bench``: one registry of suites, each importable, listed, refused if unknown."""

import importlib
from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
registry = importlib.import_module('bench.__main__')
#: The issue's ceiling on the length of any module of bench/.
MAX_LINES = 450
#: A node suite needs ROS 2; without these it cannot import (and is skipped, not failed).
ROS = {'builtin_interfaces', 'diagnostic_msgs', 'geometry_msgs', 'nav_msgs', 'rclpy',
       'sensor_msgs'}


def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'bench', *args], cwd=ROOT, text=True,
                          capture_output=True, timeout=120)


def test_every_module_of_bench_suites_is_registered():
    registered = {module for module, _, _ in registry.SUITES.values()}
    found = {f'bench.suites.{p.stem}' for p in (ROOT / 'bench' / 'suites').glob('*.py')
             if p.stem != '__init__'}
    assert found and found <= registered, found - registered


@pytest.mark.parametrize('name', sorted(registry.SUITES))
def test_each_suite_imports_and_has_its_function_and_one_line_of_help(name):
    module, function, help_ = registry.SUITES[name]
    try:
        loaded = importlib.import_module(module)
    except ImportError as exc:
        if (exc.name or '').split('.')[0] in ROS:
            pytest.skip(f'{name} needs ROS 2 ({exc.name})')
        raise
    assert callable(getattr(loaded, function))
    assert help_.strip() and '\n' not in help_


def test_list_and_no_argument_show_every_suite_with_its_help():
    for args in ((), ('--list',)):
        done = _bench(*args)
        assert done.returncode == 0, done.stderr
        lines = done.stdout.splitlines()
        for name, (_, _, help_) in registry.SUITES.items():
            assert any(line.split()[:1] == [name] and line.endswith(help_) for line in lines)


def test_an_unknown_suite_exits_2_with_one_line_on_stderr():
    done = _bench('no_such_suite', '--repeats', '1')
    assert done.returncode == 2 and done.stdout == ''
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and 'no_such_suite' in lines[0]


def test_a_suite_gets_its_own_options():
    done = _bench('yardstick', '--help')
    assert done.returncode == 0 and 'python -m bench yardstick' in done.stdout
    assert '--table-only' in done.stdout


def test_no_module_of_bench_is_over_450_lines():
    lengths = {str(p.relative_to(ROOT)): len(p.read_text().splitlines())
               for p in (ROOT / 'bench').rglob('*.py')}
    assert lengths and not {p: n for p, n in lengths.items() if n > MAX_LINES}
