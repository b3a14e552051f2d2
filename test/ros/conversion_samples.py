"""Shared inputs of the conversions tests (test_conversions*.py): frame, stamp, threats."""

from builtin_interfaces.msg import Time
import numpy as np

FRAME = 'map'
STAMP = Time(sec=12, nanosec=345)
RNG_SEED = 20240601


def _threats(n=7, seed=RNG_SEED):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(-50.0, 150.0, size=(n, 3))
    intensities = rng.uniform(1.0, 2.0e5, size=n)
    return positions, intensities
