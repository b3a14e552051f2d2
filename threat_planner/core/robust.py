"""Uncertain threat pictures and plans that hold up under them.

Intelligence on the radars is off by some metres and some intensity: a *sampled picture*
moves every threat by N(0, sigma) per axis [m] and scales its intensity F by
lognormal(0, intensity_sigma). J is linear in the intensities, so the mean J of a path over
K pictures is the J of one field holding all their threats with F / K
(:func:`merged_field`): :func:`plan_robust` minimises that expected J with the ordinary
planner on the K-times-bigger field. No-fly zones and terrain stay where the airspace
puts them (lethal spheres around the nominal threat positions included).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from threat_planner.core.cost.closed_form import Cost, segment_integrals
from threat_planner.core.cost.masking import masked_cost
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.planner import plan
from threat_planner.core.result import PlanResult
from threat_planner.core.world.airspace import Airspace
from threat_planner.core.world.threats import Box, ThreatField
from threat_planner.errors import InputError

__all__ = ['Uncertainty', 'merged_field', 'picture_costs', 'plan_robust', 'sample_pictures']

#: (segment, threat) pairs scored at once by :func:`picture_costs` (bounds its memory).
_PAIRS_AT_ONCE = 400_000


@dataclass(frozen=True)
class Uncertainty:
    """How far off the threat picture may be.

    Attributes
    ----------
    position_sigma_m : float
        Standard deviation of each coordinate of each threat [m], >= 0.
    intensity_sigma : float
        Sigma of the lognormal factor on each intensity F (its log's deviation), >= 0.

    """

    position_sigma_m: float = 0.0
    intensity_sigma: float = 0.0

    def __post_init__(self) -> None:
        """Refuse a negative, infinite or non-numeric sigma, naming it."""
        for name in ('position_sigma_m', 'intensity_sigma'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not np.isfinite(value) or value < 0:
                raise InputError(f'{name}: must be a finite number >= 0, got {value!r}')
            object.__setattr__(self, name, float(value))


def _words(seed: int | Sequence[int]) -> list[int]:
    words = [seed] if isinstance(seed, (int, np.integer)) else list(seed)
    if not words or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0
                        for v in words):
        raise InputError(f'seed: must be an integer >= 0 or a list of them, got {seed!r}')
    return [int(v) for v in words]


def sample_pictures(threats: ThreatField, samples: int, uncertainty: Uncertainty,
                    seed: int | Sequence[int] = 0, first: int = 0) -> list[ThreatField]:
    """Draw threat pictures around the nominal one.

    Picture i is drawn from its own generator, seeded by ``seed`` and i: picture 3 of a
    run of 8 is picture 3 of a run of 256, whatever ran before it.

    Parameters
    ----------
    threats : ThreatField
        The nominal picture.
    samples : int
        Pictures to draw, >= 1.
    uncertainty : Uncertainty
        Position and intensity spread.
    seed : int or sequence of int
        Seed words (>= 0).
    first : int
        Index of the first picture (draw pictures first .. first + samples - 1).

    Returns
    -------
    list of ThreatField
        The pictures, each with the nominal field's threat count.

    """
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise InputError(f'samples: must be an integer >= 1, got {samples!r}')
    words = _words(seed)
    n = len(threats)
    out = []
    for i in range(first, first + int(samples)):
        rng = np.random.default_rng(np.random.SeedSequence(words + [i]))
        moved = threats.positions + rng.normal(0.0, uncertainty.position_sigma_m, (n, 3))
        scale = rng.lognormal(0.0, uncertainty.intensity_sigma, n)
        out.append(ThreatField.from_arrays(moved, threats.intensities * scale))
    return out


def merged_field(pictures: Sequence[ThreatField]) -> ThreatField:
    """One field whose J_R is the mean J_R over the pictures: all threats, F / K.

    Parameters
    ----------
    pictures : sequence of ThreatField
        K >= 1 pictures.

    Returns
    -------
    ThreatField
        Their threats, picture after picture, each intensity divided by K.

    """
    if not pictures:
        raise InputError('pictures: need at least one picture to merge, got 0')
    k = len(pictures)
    return ThreatField.from_arrays(np.concatenate([p.positions for p in pictures]),
                                   np.concatenate([p.intensities for p in pictures]) / k)


def picture_costs(points: ArrayLike, pictures: Sequence[ThreatField], w: float,
                  airspace: Airspace | None = None) -> list[Cost]:
    """Exact J of one path on each picture (the closed form, or masked by the terrain).

    Parameters
    ----------
    points : array_like
        Path vertices (n, 3) [m].
    pictures : sequence of ThreatField
        Pictures of equal threat count.
    w : float
        Threat weight.
    airspace : Airspace, optional
        With terrain masking, each picture's J_R counts the visible parts only.

    Returns
    -------
    list of Cost
        One per picture, in order.

    """
    pts = np.asarray(points, float)
    j_l = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    if airspace is not None and airspace.masking:
        return [masked_cost(pts, p, w, airspace) for p in pictures]
    out: list[Cost] = []
    a, b = pts[:-1], pts[1:]
    n = len(pictures[0]) if pictures else 0
    step = max(1, _PAIRS_AT_ONCE // max(1, n * len(a)))
    for lo in range(0, len(pictures), step):
        group = pictures[lo:lo + step]
        if n == 0:
            j_r = np.zeros(len(group))
        else:
            pos = np.concatenate([p.positions for p in group])
            f = np.stack([p.intensities for p in group])
            integrals = segment_integrals(a, b, pos).reshape(len(a), len(group), n)
            j_r = np.einsum('skn,kn->k', integrals, f)
        out.extend(Cost(w * float(r) + (1.0 - w) * j_l, j_l, float(r)) for r in j_r)
    return out


def plan_robust(threats: ThreatField, start: ArrayLike, goal: ArrayLike, box: Box,
                config: PlannerConfig = PlannerConfig(), samples: int = 16,
                uncertainty: Uncertainty = Uncertainty(), seed: int | Sequence[int] = 0,
                airspace: Airspace | None = None,
                progress: Callable[[int, int], None] | None = None) -> PlanResult:
    """Plan the path of least expected J over ``samples`` sampled pictures.

    Parameters
    ----------
    threats : ThreatField
        The nominal picture.
    start, goal : array_like
        End points (3,) [m].
    box : Box
        Flight box.
    config : PlannerConfig
        Planner settings (the same as for a nominal plan).
    samples : int
        K, the pictures averaged over.
    uncertainty : Uncertainty
        Their spread.
    seed : int or sequence of int
        Seed words of the pictures (see :func:`sample_pictures`).
    airspace : Airspace, optional
        No-fly zones and terrain (method 'best').
    progress : callable, optional
        As :func:`~threat_planner.core.planner.plan`'s.

    Returns
    -------
    PlanResult
        The plan on the merged field: its ``cost`` is the mean J over the K pictures and
        ``problem[0]`` the merged field.

    """
    pictures = sample_pictures(threats, samples, uncertainty, seed)
    return plan(merged_field(pictures), start, goal, box, config, progress=progress,
                airspace=airspace)
