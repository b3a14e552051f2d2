"""The bench's independent detection hazard (bench/toolkit/detection_slsqp.py)."""
import sys
from pathlib import Path
import numpy as np
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from bench.toolkit import detection_slsqp as dy  # noqa: E402


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
