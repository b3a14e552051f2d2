"""Direct minimisation of J (beyond the paper) inside the box and the flight limits.

The smoothed chain balances springs against repulsion, which is not the same as least J.
Here the interior vertices move to minimise J itself with its exact gradient, inside the
flight box (bounds, raised by the minimum altitude), by the compiled projected L-BFGS of
:mod:`.lbfgs` (objective and all in numba; scipy's L-BFGS-B spent ~0.5 ms per evaluation
in its Python callback against 0.06 ms for J). Where the result breaks a flight limit
(:mod:`.limits`), an augmented Lagrangian takes over: the same L-BFGS on J plus the
Powell-Hestenes-Rockafellar term of the limit constraints, the multipliers updated between
runs, coarse to fine (10, 20, 40 segments, the multipliers carried as densities). It
replaced SLSQP (measured in ``bench/results/profile_*.txt``: SLSQP's dense QP was 70 % of
a 20-threat plan). A faint spring term keeps vertices evenly spread, because J alone does
not care where along the path they sit, and bunched vertices turn on tiny circles.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray
from threat_planner.core.cost.far_kernels import far_pairs
from threat_planner.core.cost.kernels import _FROZEN_C2, _FROZEN_C3, _frozen, _NO_PAIRS
from threat_planner.core.optimise.lagrangian_kernels import (counters, has_best, new_state,
                                                             run_rounds)
from threat_planner.core.optimise.lbfgs import minimise, objective, objective_scale
from threat_planner.core.optimise.limit_kernels import LimitTerm
from threat_planner.core.optimise.limits import FlightLimits, meets_limits
from threat_planner.core.optimise.smoothing import resample
from threat_planner.core.world.threats import Box, ThreatField

__all__ = ['aim', 'is_crowded', 'OptimisationResult', 'minimise_cost']

#: Weight of the even-spacing term relative to the length cost.
SPACING_WEIGHT = 1e-3
#: Weight of the even-spacing (length variance) term under the flight limits, where
#: bunched vertices make the constraints stiff (their gradients grow as 1 / length) and
#: the penalty would otherwise fold the path into near-zero segments.
EVEN_SPACING_WEIGHT = 1.0
#: Most pair re-picks of a cut-off minimisation.
MAX_PAIR_ROUNDS = 8
#: The optimiser aims this far inside the angle limits [deg] ...
ANGLE_MARGIN_DEG = 0.05
#: ... and this fraction above the minimum turn radius, so the exact check passes.
RADIUS_MARGIN = 2e-3
#: Augmented Lagrangian: first penalty, its growth when the violation stalls, most rounds.
PENALTY_START = 10.0
PENALTY_GROWTH = 10.0
MAX_OUTER = 6
#: At the finest level, also stop once a feasible round lowered J by less than this
#: (21 bundled cases: 2 % fewer segment-evaluations than running to OUTER_TOLERANCE, J
#: within 0.002 %; stopping at the first feasible round saved 7 % but left an unseen
#: 12-threat field 1.6 % above).
FINEST_GAIN = 1e-3
#: Stop the outer rounds once feasible and J (scaled) changed by less than this.
OUTER_TOLERANCE = 1e-5
#: Longest segment of a coarse level, in typical threat spacings: longer chords of a path
#: through a dense field cut into the threats it went around. On fresh 10,000-threat
#: fields (bench fresh, seed 1796529962) the 10- and 20-segment levels of a start at J 682
#: were at 3,340 and 1,634 and the plan ended at 1,590 (the release: 690); 1.5 against
#: 3: 10 against 6 of 105 cases at 1,000-10,000 threats above the release, worst 1.017
#: against 1.168 (without the far field's cells).
COARSE_SPACINGS = 1.5
#: Coarsest level of the constrained stage [segments], and its L-BFGS tolerance.
COARSE_LEVEL_SEGMENTS = 10
COARSE_LEVEL_TOLERANCE = 1e-5
#: Longest move of a vertex per L-BFGS iteration, in box diagonals: longer steps carried
#: vertices across threats' cores on big300_0 (J 30 to 10^6 times the direct one's).
MAX_STEP = 0.05
#: Under a cut-off, the pairs are picked again once a vertex moved this many cut-offs ...
REPICK_CUTOFFS = 0.25
#: ... and a box-only run stops (to pick them again) once a vertex is this many away.
REACH_CUTOFFS = 0.75
#: Median threat reach over the typical spacing from which a field counts as crowded.
CROWDED_REACH = 1.0
#: Outside crowded fields the constrained rounds start from the given start instead of
#: the box-only optimum only where its largest breach of the limits is this many times
#: smaller. The two often break them equally (the same segment at the same climb: of
#: the 338 such choices over bench perturbation's 66 unmoved cases, 60 were equal to
#: 1e-3 and 178 within 1.1x), and rounding chose: n120 seed 0 w 0.8 planned 490.4 from
#: the start and 408.5 from the box-only optimum with every threat moved 1 nm; now 405.4
#: either way. Crowded fields keep the lesser breach (big300_0 with limits, w 0.5 / 0.8:
#: +2.1 % and +1.8 % with the margin).
START_MARGIN = 1.1


@dataclass(frozen=True)
class OptimisationResult:
    """Outcome of the direct J minimisation.

    Attributes
    ----------
    points : ndarray
        Optimised path, (n+1, 3) [m].
    iterations : int
        L-BFGS iterations over all rounds and levels.
    evaluations : int
        Cost-and-gradient evaluations.
    rounds : int
        L-BFGS runs: 1 or 2 without binding limits, more for the augmented Lagrangian.
    constrained : bool
        The flight limits bound: the augmented Lagrangian ran.
    levels : tuple of ndarray
        Under binding limits, the answer of each coarser level, coarsest first (a
        ``gate`` that stopped the run: up to the level it stopped at, ``points`` its last).

    """

    points: NDArray
    iterations: int
    evaluations: int
    rounds: int
    constrained: bool = False
    levels: tuple = ()


def minimise_cost(points: NDArray, threats: ThreatField, w: float, box: Box | None,
                  limits: FlightLimits | None = None, cutoff: float | None = None,
                  max_iterations: int = 1000, tolerance: float = 1e-6,
                  constrained_iterations: int = 200, constrained_rounds: int = MAX_OUTER,
                  constrained_only: bool = False, box_broken: bool = False,
                  gate: Callable[[NDArray], bool] | None = None,
                  penalty: float = PENALTY_START, respace: bool = True,
                  even: float = EVEN_SPACING_WEIGHT, subdivide: bool = False
                  ) -> OptimisationResult:
    """Minimise J over the interior vertices within the box and the flight limits.

    Parameters
    ----------
    points : ndarray
        Starting path, (n+1, 3) [m]; the ends stay fixed.
    threats : ThreatField
        The threat field.
    w : float
        Threat weight, 0 < w < 1.
    box : Box or None
        Flight box (bounds for every vertex), or None for no bounds.
    limits : FlightLimits, optional
        Flight limits; None or all off for J within the box alone.
    cutoff : float, optional
        If set, count only threats within this distance of each segment [m]; the pairs
        are re-picked whenever the path has moved a quarter of it.
    max_iterations : int
        L-BFGS iteration limit of the unconstrained run.
    tolerance : float
        Stop when an iteration lowers J by less than this fraction; 1e-6 put J within
        0.05 % of the yardstick on the bundled scenarios at a tenth of the iterations full
        convergence takes.
    constrained_iterations : int
        L-BFGS iteration limit of each augmented Lagrangian round.
    constrained_only : bool
        Under binding limits, only the rounds at the start's resolution, from the start
        (a warm start near the constrained optimum: the box-only run would leave it and
        the rounds come back; from a start that broke the turn radius after resampling,
        the coarse levels ended 5.9e-5 above a cold plan, the rounds alone 9.4e-4 below);
        the start is an answer itself where it meets the limits. Without binding limits,
        the box-only run at the start's resolution alone (from it resampled to 10
        segments, warm replans of bench perturbation's fields ended up to 0.17 % above
        the previous plan with the limits off).
    box_broken : bool
        The box-only optimum of the start's basin is known to break the limits (a seed
        the slope-held screening had to hold): no box-only run, the rounds start from it.
    gate : callable, optional
        Called with each coarser level's answer under binding limits; True stops there
        (``points`` that answer), for a caller that decides level by level whether the
        finer levels are worth their cost.
    penalty : float
        First penalty of every level's augmented Lagrangian rounds (scaled objective).
    respace : bool
        With ``constrained_only``, resample the start evenly first; False: the rounds
        start from it as it is where it has the path's segments (a previous plan, whose
        spacing holds its corners: resampled evenly, the turns it met broke the radius).
    even : float
        Weight of the rounds' even-spacing term (EVEN_SPACING_WEIGHT); less lets the
        vertices sit where J wants them, from a start whose spacing is already sound.
    subdivide : bool
        Each level starts from the coarser answer subdivided (:func:`_prolong`), not only
        the finest: a second way through the levels where the first went astray.

    Returns
    -------
    OptimisationResult

    """
    limits = limits or FlightLimits()
    x = np.array(points, float)
    n = len(x)
    if n < 3:
        return OptimisationResult(x, 0, 0, 0)
    stats = _Stats()
    # The preconditioner's smooth, path-wide steps only where every threat is counted and
    # the field is not crowded: on big300_0 they crossed threat cores (limits off J +0.5 %
    # and +1.1 %); under a cut-off they carried paths into threats the pairs did not hold
    # (10,000 threats: J 3.5x the start's) and, kept within half a cut-off a run, made
    # 1,000-threat replans take 0.25-1.3 s against 0.3-0.4 s without.
    crowded = is_crowded(threats, box)
    smooth = not crowded and cutoff is None
    level = _Level(x, threats, w, box, limits, cutoff, tolerance, stats, smooth)
    x = level.clip(x)
    skip = constrained_only and limits.any_constraint
    keep = skip and meets_limits(x, limits, level.floor)
    # Coarse levels only where the threats' reaches (F^(1/4): where a threat costs as
    # much per metre as a metre of length) leave room between them: in a crowded field
    # (big300_0: reach 220 m, spacing 150 m) the coarse rounds ended in basins 3 to 300
    # times the direct rounds' J.
    counts = [n - 1]
    fewest = max(COARSE_LEVEL_SEGMENTS, _fewest_coarse_segments(x, threats, box))
    while counts[-1] // 2 >= fewest and not constrained_only and not crowded:
        counts.append(counts[-1] // 2)
    coarse = len(counts) > 1
    probe = _Level(resample(x, counts[-1]), threats, w, box, limits, cutoff,
                   COARSE_LEVEL_TOLERANCE, stats, smooth) if coarse else level
    lam, best = None, None
    if not skip and not (box_broken and limits.any_constraint):
        given = x
        # The box-only optimum, at the coarsest level first: the answer where it meets
        # the limits, else the start of the constrained rounds (at 40 segments under
        # binding limits it was dropped after up to 1,700 iterations on 10,000 threats).
        x = probe.unconstrained(probe.clip(resample(x, probe.n - 1)) if coarse else x,
                                max_iterations)
        if coarse and (not limits.any_constraint
                       or meets_limits(x, limits, probe.floor)):
            x = level.unconstrained(level.clip(resample(x, n - 1)), max_iterations)
        if not limits.any_constraint or meets_limits(x, limits, level.floor):
            return stats.result(x, False)
        # The rounds start from the box-only optimum, or from the given start (a seed
        # screened under the slope limits) where that breaks the limits clearly less
        # (START_MARGIN); in a crowded field, wherever it breaks them less at all: from a
        # box-only optimum with vertical segments the first round traded J for the
        # penalty and ended beside a threat, J 400x (big300_0, w 0.5).
        if _violation(given, limits) * (1.0 if crowded else START_MARGIN) < _violation(
                x, limits):
            x = given
    # Coarse to fine: the rounds at half the segments (and half of that, ...) find the
    # constrained basin and its multipliers for a tenth of the evaluations, and the fine
    # level starts next to its answer (measured in bench/results/profile_*.txt).
    levels: list[NDArray] = []
    for count in reversed(counts):
        finest = count == n - 1
        if levels and gate is not None and gate(levels[-1]):
            return stats.result(levels[-1], True, tuple(levels))
        if finest and skip and not respace and count == n - 1:
            path = x
        else:
            path = _prolong(x, count) if finest or subdivide else resample(x, count)
        lvl = level if finest else probe if count == probe.n - 1 else _Level(
            path, threats, w, box, limits, cutoff, COARSE_LEVEL_TOLERANCE, stats, smooth)
        x, lam, best = lvl.constrained(path, lam, penalty, constrained_iterations,
                                       constrained_rounds, keep_start=keep and finest,
                                       gain=FINEST_GAIN if finest else None, even=even)
        if not finest:
            levels.append(x if best is None else best)
    # (best None: stalled short of feasibility; the caller repairs or reports.)
    return stats.result(x if best is None else best, True, tuple(levels))


class _Stats:
    """Iterations, evaluations and runs over every level of one minimisation."""

    def __init__(self) -> None:
        self.iterations = self.evaluations = self.rounds = 0

    def add(self, nit: int, nfev: int, runs: int = 1) -> None:
        self.iterations += nit
        self.evaluations += nfev
        self.rounds += runs

    def result(self, x: NDArray, constrained: bool, levels: tuple = ()
               ) -> OptimisationResult:
        return OptimisationResult(x, self.iterations, self.evaluations, self.rounds,
                                  constrained, levels)


class _Level:
    """The minimisation at one vertex count: bounds, terms, pairs and the L-BFGS runs."""

    def __init__(self, x: NDArray, threats: ThreatField, w: float, box: Box | None,
                 limits: FlightLimits, cutoff: float | None, tolerance: float,
                 stats: _Stats, precondition: bool = True) -> None:
        n = self.n = len(x)
        self.precondition = precondition
        self.threats, self.w, self.limits, self.cutoff = threats, float(w), limits, cutoff
        self.tolerance, self.stats = tolerance, stats
        self.max_step = np.inf if box is None else MAX_STEP * box.diagonal
        j_l0 = float(np.linalg.norm(np.diff(x, axis=0), axis=1).sum()) or 1.0
        self.spring_unit = (1.0 - w) * (n - 1) / j_l0
        self.spring = SPACING_WEIGHT * self.spring_unit
        self.floor = -np.inf if box is None else float(box.lo[2])
        lo = np.full((n, 3), -np.inf)
        hi = np.full((n, 3), np.inf)
        if box is not None:
            low = box.lo.copy()
            low[2] = min(low[2] + limits.min_altitude_m, box.hi[2])
            lo[1:-1], hi[1:-1] = low, box.hi
        # The ends are variables with equal bounds: they never move.
        lo[0] = hi[0] = x[0]
        lo[-1] = hi[-1] = x[-1]
        self.lo, self.hi = lo, hi
        self.positions = _frozen(threats.positions if len(threats) else np.zeros((0, 3)))
        self.intensities = _frozen(threats.intensities)
        self.pairs = (_NO_PAIRS, _NO_PAIRS, self.positions)
        self.far = None
        if cutoff is not None and len(threats):
            # Beyond the cut-off the threats count through cells (world.far_field): the
            # pairs index the threats and then the cells' pseudo-threats.
            self.far = threats.far_field(cutoff)
            self.intensities = _frozen(self.far.intensities)
            self.far_positions = _frozen(self.far.positions)
        self._off = (np.zeros(7), np.zeros(0), np.zeros((n, 3)))

    def clip(self, x: NDArray) -> NDArray:
        """Move the path's interior vertices into the bounds."""
        return np.clip(x, self.lo, self.hi)

    def pick_pairs(self, p: NDArray) -> None:
        """Pick p's pairs under a cut-off: near threats exactly, far ones in cells."""
        if self.far is None:
            return
        self.pairs = (*far_pairs(self.far, p[:-1], p[1:]), self.far_positions)

    def value(self, p: NDArray, even: float, scale: float = 1.0) -> float:
        """Evaluate the objective without the limit term: J + spacing terms, over scale."""
        grad = np.zeros(3 * self.n)
        return objective(np.ascontiguousarray(p, float).reshape(-1), self.n, self.pairs[2],
                         self.intensities, self.w, self.pairs[:2], _FROZEN_C2, _FROZEN_C3,
                         self.spring, even, scale, self._off[0], self._off[1], 1.0,
                         self._off[1], self._off[2], grad)

    def run(self, p: NDArray, maxiter: int, reach: float = np.inf) -> NDArray:
        """One box-only L-BFGS run from p, scaled by its value; the minimiser, (n, 3)."""
        off = self._off
        z, _, nit, nfev = minimise(
            np.ascontiguousarray(p, float).reshape(-1), self.lo.reshape(-1),
            self.hi.reshape(-1), self.pairs[2], self.intensities, self.w, self.pairs[:2],
            _FROZEN_C2, _FROZEN_C3, self.spring, 0.0, 0.0, off[0], off[1], 1.0, off[1],
            off[2], maxiter, self.tolerance, max_step=self.max_step,
            precondition=self.precondition, reach=reach)
        self.stats.add(nit, nfev)
        return z.reshape(self.n, 3)

    def unconstrained(self, x: NDArray, maxiter: int) -> NDArray:
        """Least J within the bounds alone (re-picking the pairs under a cut-off)."""
        # With a cut-off the near threats are those of the path where they were picked; a
        # path that has moved far since may have flown towards threats it does not see,
        # so re-pick and continue until it stays within a quarter of the cut-off.
        # A run stops once a vertex is REACH_CUTOFFS from where the pairs were picked:
        # beyond, it slid through threats it did not see (scale1000.yaml, limits off: J
        # 892 against 592 with the stop, for a fifteenth of the pair evaluations).
        reach = np.inf if self.cutoff is None else REACH_CUTOFFS * self.cutoff
        for _ in range(MAX_PAIR_ROUNDS if self.cutoff is not None else 1):
            self.pick_pairs(x)
            # Dimensionless objective: the tolerances then mean the same everywhere.
            moved = self.run(x, maxiter, reach)
            shift = float(np.max(np.linalg.norm(moved - x, axis=1)))
            x = moved
            if self.cutoff is None or shift < REPICK_CUTOFFS * self.cutoff:
                break
        return x

    def constrained(self, x: NDArray, lam: NDArray | None, mu: float, maxiter: int,
                    rounds: int = MAX_OUTER, keep_start: bool = False,
                    gain: float | None = None, even: float = EVEN_SPACING_WEIGHT) -> tuple:
        """Augmented Lagrangian rounds from x (multipliers lam of a coarser level or None).

        Returns ``(x, (term, lam), best)``: the last iterate, its multipliers with their
        term (for the next finer level) and the least-J feasible iterate or None (least
        J, not least objective: the even-spacing term is a means, not the goal). Every
        level starts at penalty ``mu``: carrying the coarse level's grown penalty made the
        fine rounds too stiff (uniform20_0 at w 0.8: infeasible, J +12 %).
        ``gain`` also stops at a feasible round that lowered J by less than that fraction
        from the best feasible one before (the finest level, FINEST_GAIN); ``even`` weighs
        the even-spacing term (EVEN_SPACING_WEIGHT x the spring unit). Afterwards
        ``self.trace`` (rounds, 3) holds each round's J, feasibility and violation.
        """
        x = self.clip(x)
        self.pick_pairs(x)
        even = even * self.spring_unit
        scale = float(objective_scale(self.value(x, even)))
        term = LimitTerm(aim(self.limits), self.n)
        lam = np.zeros(term.rows) if lam is None else term.transfer(lam)
        z = np.ascontiguousarray(x, float).reshape(-1).copy()
        best = z.copy()
        state = new_state(mu, self.value(x, 0.0) if keep_start else np.inf)
        self.trace = np.full((rounds, 3), np.nan)
        lim = self.limits
        repick = np.inf if self.cutoff is None else REPICK_CUTOFFS * self.cutoff
        while run_rounds(z, self.lo.reshape(-1), self.hi.reshape(-1), self.pairs[2],
                         self.intensities, self.w, self.pairs[:2], _FROZEN_C2, _FROZEN_C3,
                         self.spring, even, scale, term.kernel_args(), lam, maxiter,
                         self.tolerance, self.max_step, self.precondition, rounds,
                         -1.0 if gain is None else gain, PENALTY_GROWTH, OUTER_TOLERANCE,
                         np.array([lim.max_climb_deg, lim.max_dive_deg,
                                   lim.min_turn_radius_m, lim.min_altitude_m]),
                         self.floor, z.copy(), repick, best, state, self.trace):
            # As in unconstrained: a path that moved far may near threats unseen.
            self.pick_pairs(z.reshape(self.n, 3))
        self.stats.add(*counters(state))
        return (z.reshape(self.n, 3), (term, lam),
                best.reshape(self.n, 3) if has_best(state) else None)


def _prolong(x: NDArray, count: int) -> NDArray:
    """Return x at ``count`` segments: cubic B-spline subdivision where that doubles them.

    Linear interpolation halves the turn radius at every old vertex (its neighbours come
    twice as close with the same turn), so a coarse answer that met the radius starts the
    fine rounds far outside it; subdivision spreads each turn over two vertices (on the
    21 bundled cases: uniform20_0 at w 0.8 needed 57 % fewer segment-evaluations and
    ended 1.5 % lower in J). Both are convex combinations: the path stays in the box.
    Used into the finest level only: into the middle one it cost more than it saved.
    """
    if 2 * (len(x) - 1) != count:
        return resample(x, count)
    out = np.empty((count + 1, 3))
    out[0::2] = x
    out[1::2] = 0.5 * (x[:-1] + x[1:])
    out[2:-2:2] = (x[:-2] + 6.0 * x[1:-1] + x[2:]) / 8.0
    return out


def aim(limits: FlightLimits) -> FlightLimits:
    """Return the limits the optimisers aim at: ANGLE_MARGIN_DEG and RADIUS_MARGIN inside."""
    return limits.tightened(ANGLE_MARGIN_DEG, RADIUS_MARGIN)


def _violation(x: NDArray, limits: FlightLimits) -> float:
    """Largest breach of the limits' smooth constraints (0 where they hold)."""
    return float(np.max(-LimitTerm(limits, len(x)).values(x), initial=0.0))


def _fewest_coarse_segments(x: NDArray, threats: ThreatField, box: Box | None) -> float:
    """Fewest segments of a coarse level of x: each at most COARSE_SPACINGS spacings."""
    if box is None or len(threats) == 0:
        return 0.0
    length = float(np.linalg.norm(np.diff(x, axis=0), axis=1).sum())
    return length / (COARSE_SPACINGS * threats.typical_spacing(box))


def is_crowded(threats: ThreatField, box: Box | None) -> bool:
    """Whether the median threat's reach F^(1/4) [m] is CROWDED_REACH of the spacing."""
    if box is None or len(threats) == 0:
        return False
    reach = threats.median_intensity ** 0.25
    return reach >= CROWDED_REACH * threats.typical_spacing(box)
