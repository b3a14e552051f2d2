"""The problems the suites plan: bundled scenarios, references and generated fields.

The generated ones are seeded: a given (n, seed) is always the same problem.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Iterator

import numpy as np
from numpy.typing import NDArray

from bench.toolkit.repo import DATA
from threat_planner.core.inputs.scenario import load_scenario, Scenario
from threat_planner.core.world.threats import Box, ThreatField

#: The bundled 20-threat scenarios the speed, perturbation and before/after suites plan.
SCENARIOS = ['uniform20_0', 'uniform20_1', 'weak20_0', 'strongweak_0', 'clustered_0',
             'ground_0', 'coplanar_0']
#: Threat weights of every bundled case.
WS = (0.2, 0.5, 0.8)
#: The small scenarios of a ``--quick`` run.
QUICK_SCENARIOS = ('uniform20_0', 'weak20_0')
#: PlannerConfig fields that switch the flight limits off (climb, dive, turn radius).
LIMITS_OFF = {'max_climb_deg': 90.0, 'max_dive_deg': 90.0, 'min_turn_radius_m': 0.0}
#: PlannerConfig fields that switch the UAV angle limits off (pitch <= 90, turn <= 180
#: always hold): the rules OMPL, the grid floor and the reference play by.
NO_ANGLE_LIMITS = {'max_pitch_deg': 90.0, 'max_turn_deg': 180.0}
#: Threat counts and seeds of the random fields (see :func:`random_fields`).
RANDOM_SIZES = (12, 20, 35, 60, 120)
RANDOM_SEEDS = (0, 1, 2)


def load_reference(path: str | Path) -> dict[tuple[str, float], dict[str, float]]:
    """Read the yardstick's ``reference.json``.

    Parameters
    ----------
    path : str or Path
        The JSON file, keyed ``"scenario@w"`` with values ``{"J": ..., "seconds": ...}``.

    Returns
    -------
    dict
        ``(scenario, w) -> {"J": float, "seconds": float}``, w rounded to 6 decimals.
    """
    data = json.loads(Path(path).read_text())
    out: dict[tuple[str, float], dict[str, float]] = {}
    for key, value in data.items():
        name, _, w = key.rpartition('@')
        if not name:
            raise ValueError(f'{path}: key {key!r} is not "scenario@w"')
        out[(name, round(float(w), 6))] = {'J': float(value['J']),
                                           'seconds': float(value.get('seconds', math.nan))}
    return out


def scale_problem(n: int, seed: int = 0) -> tuple[ThreatField, NDArray, NDArray, Box]:
    """Make a random problem with n threats at the density of the 20-threat scenarios.

    Threats are uniform in a cube of side ``100 (n / 20)^(1/3)`` m (100 m for 20), with
    intensities uniform in [1e5, 4e5] like ``uniform20_*``; start and goal sit at opposite
    corners at mid height, like ``scale1000.yaml``.

    Parameters
    ----------
    n : int
        Number of threats.
    seed : int
        Random seed.

    Returns
    -------
    threats, start, goal, box
        The problem.
    """
    side = 100.0 * (n / 20.0) ** (1.0 / 3.0)
    rng = np.random.default_rng([seed, n])
    positions = rng.uniform(0.0, side, size=(n, 3))
    intensities = rng.uniform(1e5, 4e5, size=n)
    box = Box.from_corners([0.0, 0.0, 0.0], [side, side, side])
    start = np.array([0.0, 0.0, side / 2])
    goal = np.array([side, side, side / 2])
    return ThreatField.from_arrays(positions, intensities), start, goal, box


def moved_threats(threats: ThreatField, diagonal: float, seed: int = 7,
                  fraction: float = 0.005) -> ThreatField:
    """Return the threats each moved by at most ``fraction`` of the box diagonal.

    The speed suite's small change for warm replans: every coordinate shifted uniformly by
    up to ``fraction * diagonal / sqrt(3)`` [m] (random ``seed``), intensities kept.
    """
    rng = np.random.default_rng(seed)
    shift = rng.uniform(-1, 1, threats.positions.shape) * fraction * diagonal / np.sqrt(3)
    return ThreatField.from_arrays(threats.positions + shift, threats.intensities)


def random_scenario(n: int, seed: int = 0) -> Scenario:
    """Make a 100 m box with `n` random threats; start and goal on opposite faces."""
    rng = np.random.default_rng(seed)
    threats = ThreatField.from_arrays(rng.uniform(1.0, 99.0, size=(n, 3)),
                                      10.0 ** rng.uniform(3.0, 6.0, size=n))
    return Scenario(name=f'random{n}', frame_id='map',
                    box=Box.from_corners([0.0, 0.0, 0.0], [100.0, 100.0, 100.0]),
                    start=np.array([0.0, 0.0, 50.0]), goal=np.array([100.0, 100.0, 50.0]),
                    threats=threats, description='')


def random_fields() -> Iterator[tuple[str, ThreatField, NDArray, NDArray, Box, float]]:
    """Yield ``(name, threats, start, goal, box, w)`` of the 45 random fields.

    Each is ``scale_problem(n, 100 + seed)`` for n in :data:`RANDOM_SIZES` and seed in
    :data:`RANDOM_SEEDS`, every intensity scaled by a random factor in [0.3, 3] and the
    start and goal heights drawn uniformly in the box, at every w of :data:`WS`.
    """
    for n in RANDOM_SIZES:
        for seed in RANDOM_SEEDS:
            threats, s, t, box = scale_problem(n, 100 + seed)
            rng = np.random.default_rng([n, seed])
            s, t = s.copy(), t.copy()
            s[2] = rng.uniform(box.lo[2], box.hi[2])
            t[2] = rng.uniform(box.lo[2], box.hi[2])
            threats = ThreatField.from_arrays(
                threats.positions, threats.intensities * rng.uniform(0.3, 3.0, len(threats)))
            for w in WS:
                yield f'n{n} seed {seed} w {w}', threats, s, t, box, w


def bundled_cases() -> Iterator[tuple[str, ThreatField, NDArray, NDArray, Box, float]]:
    """Yield ``(name@w, threats, start, goal, box, w)`` of the bundled 20-threat cases."""
    for name in SCENARIOS:
        sc = load_scenario(DATA / f'{name}.yaml')
        for w in WS:
            yield f'{name}@{w}', sc.threats, sc.start, sc.goal, sc.box, w
