"""The bench's own detection model (bench/toolkit/detection_yardstick.py): H and its gradient."""

import importlib
from pathlib import Path
import sys

import numpy as np
import pytest

from threat_planner.core.detection.hazard import path_hazard
from threat_planner.core.detection.model import DetectionModel

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
dy = importlib.import_module('bench.toolkit.detection_yardstick')


@pytest.mark.parametrize('swerling', [0, 1])
def test_independent_hazard_agrees_with_product(swerling):
    pos = np.array([[30.0, 32.0, 50.0], [70.0, 60.0, 45.0]])
    f = np.array([2e5, 3e5])
    path = np.array([[0.0, 0, 50], [40, 20, 50], [100, 100, 50]])
    p, h, per = dy.independent_hazard(path, pos, f, swerling=swerling, step=0.05)
    rep = path_hazard(path, pos, f, DetectionModel(swerling=swerling))
    assert h == pytest.approx(rep.hazard, rel=1e-6)
    assert p == pytest.approx(rep.p_detect, rel=1e-6)


def test_gradient_matches_central_differences():
    rng = np.random.default_rng(0)
    q, f = rng.uniform(0, 100, (5, 3)), rng.uniform(1e5, 4e5, 5)
    p = np.linspace([0, 0, 50], [100, 100, 50], 9) + rng.normal(0, 3, (9, 3))
    _, g = dy.hazard(p, q, f, intervals=32, want_grad=True)
    for i, k in [(2, 0), (4, 2), (7, 1)]:
        a, b = p.copy(), p.copy()
        a[i, k] += 1e-5
        b[i, k] -= 1e-5
        fd = (dy.hazard(a, q, f, intervals=32) - dy.hazard(b, q, f, intervals=32)) / 2e-5
        assert abs(g[i, k] - fd) <= 1e-4 * abs(fd) + 1e-11  # FD of H ~ 1e-5 at rounding


def test_far_field_is_the_false_alarm_floor():
    p = np.array([[0.0, 0, 0], [100.0, 0, 0]])
    h = dy.hazard(p, np.array([[0.0, 1e6, 0]]), np.array([1e5]))
    assert abs(h - 1e-6 * 100 / 20) < 1e-12
