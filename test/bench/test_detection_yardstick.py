"""Fast test of the independent detection check (bench/toolkit/detection_yardstick.py)."""

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
