"""One planning problem, the candidate paths of its methods, and the stage clock."""

from __future__ import annotations

from dataclasses import dataclass, field
import time
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.closed_form import Cost
from threat_planner.core.cost.kernels import path_cost as compiled_cost
from threat_planner.core.cost.masking import masked_cost
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.network.partition import Network
from threat_planner.core.network.search import EdgeCosts
from threat_planner.core.optimise.limits import check_limits, FlightLimits, LimitCheck
from threat_planner.core.optimise.smoothing import AngleCheck, check_angles, resample, smooth
from threat_planner.core.world.threats import Box, ThreatField

__all__ = ['Candidate', 'Clock', 'Problem', 'smooth_route']


class Clock:
    """Accumulates wall time per named stage."""

    def __init__(self) -> None:
        self.ms: dict[str, float] = {}
        self._t0 = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Charge the time since the previous lap to `stage`."""
        now = time.perf_counter()
        self.ms[stage] = self.ms.get(stage, 0.0) + 1e3 * (now - self._t0)
        self._t0 = now


@dataclass
class Problem:
    """One planning problem and what the methods share while solving it."""

    threats: ThreatField
    s: NDArray
    t: NDArray
    box: Box
    config: PlannerConfig
    network: Network
    edge_j: Optional[EdgeCosts]
    clock: Clock
    progress: Optional[Callable[[int, int], None]] = None
    candidates: dict[tuple[int, int], float] = field(default_factory=dict)
    k_sweep: dict[float, float] = field(default_factory=dict)
    # airspace hook (issue 12): zones and terrain; None plans exactly as before.
    airspace: Optional['Airspace'] = None  # noqa: F821
    #: Called with the network route's polyline and its exact cost as soon as the search
    #: has one, before smoothing and optimisation (a caller that may stop the plan early
    #: keeps it as the best path so far).
    on_initial: Optional[Callable[[NDArray, Cost], None]] = None

    def route_found(self, seq: list[int]) -> None:
        """Hand the route `seq` (S, its nodes, T) to :attr:`on_initial`, if set."""
        if self.on_initial is not None and seq:
            points = np.vstack([self.s, self.network.nodes[seq], self.t])
            self.on_initial(points, self.cost(points))

    def cost(self, points: NDArray) -> Cost:
        """Exact J of a path through this problem's threats (masked if the terrain masks)."""
        if self.airspace is not None and self.airspace.masking:
            return masked_cost(points, self.threats, self.config.w, self.airspace)
        return compiled_cost(points, self.threats.positions, self.threats.intensities,
                             self.config.w)

    @property
    def limits(self) -> FlightLimits:
        """The physical flight limits in force."""
        return FlightLimits.of(self.config)

    def check(self, points: NDArray) -> LimitCheck:
        """Measure a path's climb, dive, turn radius and altitude against the limits."""
        return check_limits(points, self.limits, float(self.box.lo[2]))


@dataclass
class Candidate:
    """One path under consideration, from its network route to its final form."""

    seq: list[int]
    initial: NDArray
    smoothed: NDArray | None
    smoothed_cost: Cost | None
    final: NDArray
    k: float
    steps: int
    converged: bool
    cost: Cost
    angles: AngleCheck
    seed: str = 'route 0'
    limit_check: Optional[LimitCheck] = None
    #: Relative J gap between the best and the second-best screened basin ('best').
    basin_margin: float = float('inf')
    #: The flight limits bound in the final minimisation ('best').
    limits_bound: bool = False
    #: Its answers at the coarser levels under binding limits, coarsest first.
    levels: tuple = ()
    #: cost_model 'detection' (issue 43): its w H + (1 - w) L / L_0 (L / L_0 under a
    #: bound), and what became of a bound on P_detect ('' none, 'met' or why not).
    objective: Optional[float] = None
    detection_status: str = ''


def smooth_route(p: Problem, seq: list[int], k: float) -> Candidate:
    """Smooth one network route with spring coefficient k (paper §3.4)."""
    cfg = p.config
    initial = np.vstack([p.s, p.network.nodes[seq], p.t])
    # Network nodes may sit in the box's margin; the chain starts inside the box.
    chain = p.box.clip(resample(initial, cfg.n_points))
    r = smooth(chain, p.threats.positions, p.threats.intensities, k, cfg.damping, cfg.mass,
               cfg.q, max_steps=cfg.max_smoothing_steps, bounds=(p.box.lo, p.box.hi))
    pts = r.points
    c = p.cost(pts)
    if not np.isfinite(c.J):
        # The chain came to rest on a threat (pinned there by a wall): the resampled
        # route itself is the better answer.
        pts = chain
        c = p.cost(pts)
    return Candidate(seq=seq, initial=initial, smoothed=pts, smoothed_cost=c, final=pts, k=k,
                     steps=r.steps, converged=r.converged, cost=c,
                     angles=check_angles(pts, cfg.max_pitch_deg, cfg.max_turn_deg),
                     limit_check=p.check(pts))
