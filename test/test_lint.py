"""Code style, as ament_flake8 and ament_pep257 check it in a ROS build."""

from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ['threat_planner', 'test', 'bench', 'launch', 'setup.py']


@pytest.mark.linter
def test_flake8():
    pytest.importorskip('flake8')
    present = [s for s in SOURCES if (ROOT / s).exists()]
    p = subprocess.run([sys.executable, '-m', 'flake8', *present], cwd=ROOT,
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stdout + p.stderr


@pytest.mark.linter
def test_pep257():
    pytest.importorskip('pydocstyle')
    p = subprocess.run([sys.executable, '-m', 'pydocstyle', 'threat_planner'], cwd=ROOT,
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stdout + p.stderr
