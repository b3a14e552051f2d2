"""The benchmark's yardsticks per (scenario, w), every one checked inside the box.

* **in-box** (limits off): the bench's own
  :func:`bench.toolkit.yardstick.in_box_yardstick`, cached in
  ``bench/results/yardstick.json`` by ``python -m bench yardstick``; where the bench has no
  value, ``/work/shared/scenarios/reference_box.json`` (the same recipe computed elsewhere,
  paths in ``reference_box/``). Where both exist, their ratio is reported as a check.
* **limited** (climb, dive, turn radius): the bench's
  :func:`bench.toolkit.yardstick.limited_yardstick`
  from the same cache; its limits are the ones ``best (limits on)`` is run with.
* **lower bound**: ``reference.json`` (unbounded L-BFGS: its paths leave the box), shown
  only as a labelled lower bound, never as a yardstick.

Every stored path is re-scored with ``path_cost`` and checked to lie in the box (to 1e-6
of the box diagonal); a case whose stored J disagrees or whose path leaves the box raises.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import math
from pathlib import Path

import numpy as np

from bench.toolkit.flight_limits import check_limits, Limits
from bench.toolkit.repo import DATA, RESULTS, SHARED
from threat_planner.core.cost.closed_form import path_cost

CACHE = RESULTS / 'yardstick.json'
REFERENCE_BOX = SHARED / 'reference_box.json'
#: Relative agreement required between a stored J and path_cost of the stored path.
J_TOL = 1e-6


@dataclass(frozen=True)
class Yardsticks:
    """The yardsticks of one case (None where there is no value).

    Attributes
    ----------
    in_box : float or None
        Least in-box J, limits off.
    in_box_source : str
        ``'bench G^3'`` or ``'reference_box.json'`` (or ``'-'``).
    box_check : float or None
        bench in-box J / reference_box.json J where both exist.
    limited : float or None
        Least J inside the box within ``limits``.
    limits : Limits or None
        The limited yardstick's climb, dive and turn-radius limits.
    lower_bound : float or None
        ``reference.json`` J (unbounded: leaves the box).
    """

    in_box: float | None
    in_box_source: str
    box_check: float | None
    limited: float | None
    limits: Limits | None
    lower_bound: float | None


def _checked_j(path: np.ndarray, stored: float, sc, w: float, what: str) -> float:
    tol = 1e-6 * sc.box.diagonal
    if np.any(path < sc.box.lo - tol) or np.any(path > sc.box.hi + tol):
        raise ValueError(f'{what}: stored path leaves the box')
    j = path_cost(path, sc.threats.positions, sc.threats.intensities, w).J
    if not abs(j - stored) <= J_TOL * abs(j):
        raise ValueError(f'{what}: stored J {stored} but path_cost {j}')
    return j


def default_limits(sc) -> Limits:
    """Return the limited yardstick's default limits: 30 / 30 deg, 0.1 x shortest edge [m].

    The edge is the box's shortest horizontal one.
    """
    span = sc.box.hi - sc.box.lo
    return Limits(30.0, 30.0, 0.1 * float(min(span[0], span[1])))


class YardstickTable:
    """All yardsticks, loaded once.

    Parameters
    ----------
    cache : Path
        The bench's ``yardstick.json``.
    reference_box : Path
        ``reference_box.json`` (its paths in the sibling folder ``reference_box/``).
    reference : Path
        ``reference.json`` (lower bounds).
    """

    def __init__(self, cache: Path = CACHE, reference_box: Path = REFERENCE_BOX,
                 reference: Path | None = None) -> None:
        self.cache = json.loads(cache.read_text()) if cache.exists() else {}
        self.ref_box = json.loads(reference_box.read_text()) if reference_box.exists() else {}
        self.ref_box_dir = reference_box.parent / 'reference_box'
        reference = reference or DATA / 'reference.json'
        self.lower = json.loads(reference.read_text()) if reference.exists() else {}

    def get(self, sc, w: float) -> Yardsticks:
        """Check and return the yardsticks of scenario ``sc`` at ``w``."""
        key = f'{sc.name}@{w:g}'
        bench = self.cache.get(key)
        bench_j = limited = limits = None
        if bench:
            bench_j = _checked_j(np.asarray(bench['in_box']['path']), bench['in_box']['J'],
                                 sc, w, f'yardstick.json {key} in_box')
            lim = bench['limited']
            limits = Limits(**{k: lim['limits'][k] for k in
                               ('max_climb_deg', 'max_dive_deg', 'min_turn_radius_m')})
            if lim['feasible'] and math.isfinite(lim['J']):
                path = np.asarray(lim['path'])
                limited = _checked_j(path, lim['J'], sc, w, f'yardstick.json {key} limited')
                if not check_limits(path, limits):
                    raise ValueError(f'yardstick.json {key} limited: path breaks its limits')
        box_j = None
        npy = self.ref_box_dir / f'{key}.npy'
        if key in self.ref_box and npy.exists():
            box_j = _checked_j(np.load(npy), self.ref_box[key]['J'], sc, w,
                               f'reference_box.json {key}')
        grid = bench['settings']['grid'] if bench else None
        if bench_j is not None:
            source, value = f'bench {grid}^3', bench_j
        elif box_j is not None:
            source, value = 'reference_box.json', box_j
        else:
            source, value = '-', None
        check = bench_j / box_j if bench_j is not None and box_j is not None else None
        lower = self.lower.get(key, {}).get('J')
        return Yardsticks(value, source, check, limited, limits,
                          float(lower) if lower is not None else None)
