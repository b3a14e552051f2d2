"""The layers hold: the planning core and the command line's ``plan`` load no ROS."""

from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Loaded by importing each of these, nothing from rclpy or a message package may be.
ROS_FREE = [
    'threat_planner',
    'threat_planner.core',
    'threat_planner.core.planner',
    'threat_planner.core.scenario',
    'threat_planner.cli',
    'threat_planner.cli.main',
]

PROBE = r"""
import importlib, json, sys
importlib.import_module(sys.argv[1])
ros = sorted(m for m in sys.modules
             if m.split('.')[0] in ('rclpy', 'rosidl_parser', 'rosidl_runtime_py')
             or m.split('.')[0].endswith('_msgs') or m.split('.')[0].endswith('_interfaces'))
print(json.dumps(ros))
"""


@pytest.mark.parametrize('module', ROS_FREE)
def test_core_imports_no_ros(module):
    p = subprocess.run([sys.executable, '-c', PROBE, module], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == '[]', f'{module} loads {p.stdout.strip()}'


def test_cli_plan_loads_no_ros(tmp_path):
    """Planning a scenario from the command line (no --record) never touches rclpy."""
    probe = (
        'import sys, json\n'
        'from threat_planner.cli import main\n'
        f'code = main(["plan", {str(ROOT / "test" / "data" / "weak20_0.yaml")!r}, '
        f'"--json", {str(tmp_path / "out.json")!r}])\n'
        'ros = [m for m in sys.modules if m.split(".")[0] == "rclpy" '
        'or m.split(".")[0].endswith("_msgs")]\n'
        'print(json.dumps(ros)); sys.exit(code)\n')
    p = subprocess.run([sys.executable, '-c', probe], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == '[]'
    assert (tmp_path / 'out.json').exists()


def test_the_probe_sees_ros_when_it_is_loaded():
    """The check above can fail: importing the node package does load rclpy."""
    p = subprocess.run([sys.executable, '-c', PROBE, 'threat_planner.ros.node'], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert 'rclpy' in p.stdout


def test_no_module_is_over_450_lines():
    sizes = {str(f.relative_to(ROOT)): len(f.read_text().splitlines())
             for f in (ROOT / 'threat_planner').rglob('*.py')}
    assert {f: n for f, n in sizes.items() if n > 450} == {}
