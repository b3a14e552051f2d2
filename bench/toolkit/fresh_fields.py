"""Families of random threat fields for ``python -m bench fresh``: new ones every seed.

Every family puts ``n`` threats in a cube of side ``100 (n / 20)^(1/3)`` m (the density of
the bundled 20-threat scenarios, 100 m for 20) and flies from the corner ``(0, 0, z_s)`` to
the opposite one ``(side, side, z_g)``. Threats keep at least 5 % of the side from the
vertical edges through start and goal (x and y in [5 %, 95 %] of the side), so no end
point sits in a threat. :func:`make_field` seeds a generator from ``(seed, family, n, k)``:
the same four always give the same field, bit for bit, and any other seed a new one.

The generators return plain arrays (a :class:`Field`), so a process with another
checkout's package can build its own threat field and box from them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

#: x and y of every threat, as fractions of the side: clear of start and goal.
INNER = (0.05, 0.95)


@dataclass(frozen=True)
class Field:
    """One generated problem, as arrays.

    Attributes
    ----------
    positions : ndarray, shape (n, 3)
        Threat positions [m].
    intensities : ndarray, shape (n,)
        Threat intensities F.
    start, goal : ndarray, shape (3,)
        End points [m], inside the box.
    lo, hi : ndarray, shape (3,)
        Corners of the flight box [m].
    """

    positions: NDArray
    intensities: NDArray
    start: NDArray
    goal: NDArray
    lo: NDArray
    hi: NDArray

    def problem(self) -> tuple:
        """Return ``(threats, start, goal, box)`` built with this process's package."""
        from threat_planner import Box, ThreatField
        return (ThreatField.from_arrays(self.positions, self.intensities), self.start,
                self.goal, Box.from_corners(self.lo, self.hi))

    def as_json(self) -> dict:
        """Return the field as lists (floats keep every bit through ``json``)."""
        return {k: getattr(self, k).tolist() for k in
                ('positions', 'intensities', 'start', 'goal', 'lo', 'hi')}


def side_of(n: int) -> float:
    """Return the cube's side [m] for n threats: ``100 (n / 20)^(1/3)``."""
    return 100.0 * (n / 20.0) ** (1.0 / 3.0)


def _field(positions: NDArray, intensities: NDArray, side: float, z_start: float,
           z_goal: float) -> Field:
    return Field(np.asarray(positions, float), np.asarray(intensities, float),
                 np.array([0.0, 0.0, z_start]), np.array([side, side, z_goal]),
                 np.zeros(3), np.full(3, side))


def _heights(rng: np.random.Generator, side: float, lo: float, hi: float) -> tuple:
    """Start and goal heights drawn uniformly in [lo, hi] of the side."""
    z = rng.uniform(lo, hi, 2) * side
    return float(z[0]), float(z[1])


def uniform(n: int, rng: np.random.Generator) -> Field:
    """Uniform threats in the cube, as issue 42 drew them.

    Every coordinate uniform in [5 %, 95 %] of the side, F uniform in [1e5, 4e5], start
    ``(0, 0, side/2)`` and goal ``(side, side, side/2)``: the family on which issue 42 saw
    the default plan at 10,000 threats reach 1.6-2.1x the release's J.
    """
    side = side_of(n)
    positions = rng.uniform(*INNER, size=(n, 3)) * side
    intensities = rng.uniform(1e5, 4e5, n)
    return _field(positions, intensities, side, side / 2, side / 2)


def clustered(n: int, rng: np.random.Generator) -> Field:
    """Gaussian clusters: a few of them, with open space between.

    3-6 clusters, centres uniform in [20 %, 80 %] of the side, each with its own spread
    (standard deviation 4-10 % of the side) and share of the threats; positions clipped
    into [5 %, 95 %]. F uniform in [1e5, 4e5]; start and goal heights uniform in
    [20 %, 80 %] of the side.
    """
    side = side_of(n)
    k = int(rng.integers(3, 7))
    centres = rng.uniform(0.2, 0.8, size=(k, 3))
    spread = rng.uniform(0.04, 0.10, k)
    which = rng.choice(k, size=n, p=rng.dirichlet(np.full(k, 2.0)))
    positions = centres[which] + rng.normal(size=(n, 3)) * spread[which, None]
    positions = np.clip(positions, *INNER) * side
    intensities = rng.uniform(1e5, 4e5, n)
    return _field(positions, intensities, side, *_heights(rng, side, 0.2, 0.8))


def ground(n: int, rng: np.random.Generator) -> Field:
    """Ground radars: every threat in the lowest 10 % of the box.

    x and y uniform in [5 %, 95 %] of the side, z uniform in [0, 10 %] (the floor is the
    box's, so plans can not pass under them); F uniform in [1e5, 4e5]; start and goal
    heights uniform in [20 %, 60 %], above the radars.
    """
    side = side_of(n)
    positions = np.column_stack([rng.uniform(*INNER, size=(n, 2)),
                                 rng.uniform(0.0, 0.10, n)]) * side
    intensities = rng.uniform(1e5, 4e5, n)
    return _field(positions, intensities, side, *_heights(rng, side, 0.2, 0.6))


def strong_weak(n: int, rng: np.random.Generator) -> Field:
    """Weak threats with a few strong ones: F over two decades.

    Positions as :func:`uniform`; F log-uniform in [3e4, 3e5], except a strong 5 % (at least
    one) log-uniform in [1e6, 3e6]; start and goal heights uniform in [10 %, 90 %].
    """
    side = side_of(n)
    positions = rng.uniform(*INNER, size=(n, 3)) * side
    intensities = 10.0 ** rng.uniform(np.log10(3e4), np.log10(3e5), n)
    strong = rng.choice(n, size=max(1, n // 20), replace=False)
    intensities[strong] = 10.0 ** rng.uniform(6.0, np.log10(3e6), len(strong))
    return _field(positions, intensities, side, *_heights(rng, side, 0.1, 0.9))


def coplanar(n: int, rng: np.random.Generator) -> Field:
    """Threats within a thin slab: near-coplanar points, hard for the 3-D Delaunay.

    A plane through a point near the centre (within 10 % of the side) with a random normal;
    each threat is a point drawn uniformly in [5 %, 95 %]^3 projected onto that plane, then
    offset along the normal by up to 0.5 % of the side either way, and kept only if it is
    still inside [5 %, 95 %]^3 (drawn again until n are). F uniform in [1e5, 4e5]; start
    and goal heights uniform in [20 %, 80 %].
    """
    side = side_of(n)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    origin = 0.5 + rng.uniform(-0.1, 0.1, 3)
    kept: list[NDArray] = []
    count = 0
    while count < n:
        p = rng.uniform(*INNER, size=(2 * n, 3))
        p -= np.outer((p - origin) @ normal, normal)
        p += np.outer(rng.uniform(-0.005, 0.005, len(p)), normal)
        p = p[np.all((p >= INNER[0]) & (p <= INNER[1]), axis=1)]
        kept.append(p)
        count += len(p)
    positions = np.concatenate(kept)[:n] * side
    intensities = rng.uniform(1e5, 4e5, n)
    return _field(positions, intensities, side, *_heights(rng, side, 0.2, 0.8))


#: Family name -> generator, in a fixed order (the order seeds each family's fields).
FAMILIES: dict[str, Callable[[int, np.random.Generator], Field]] = {
    'uniform': uniform, 'clustered': clustered, 'ground': ground,
    'strongweak': strong_weak, 'coplanar': coplanar}


def make_field(family: str, n: int, seed: int, k: int = 0) -> Field:
    """Return field ``k`` of ``family`` with ``n`` threats under ``seed``.

    Parameters
    ----------
    family : str
        A key of :data:`FAMILIES`.
    n : int
        Number of threats.
    seed : int
        The run's seed.
    k : int
        Which field of this family and size (0, 1, ...).

    Returns
    -------
    Field
        The same arrays for the same arguments.
    """
    index = list(FAMILIES).index(family)
    return FAMILIES[family](n, np.random.default_rng([seed, index, n, k]))
