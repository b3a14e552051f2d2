"""PlanResult: everything one plan produced, and its ``--json`` summary."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.closed_form import Cost
from threat_planner.core.detection.hazard import DetectionReport, path_hazard
from threat_planner.core.detection.model import DetectionModel
from threat_planner.core.inputs.settings import PLANNER_SETTINGS
from threat_planner.core.optimise.limits import FlightLimits, LimitCheck
from threat_planner.core.optimise.smoothing import AngleCheck
from threat_planner.core.trajectory import point_times
from threat_planner.core.world.threats import Box, ThreatField

if TYPE_CHECKING:  # the network's module imports scipy.spatial, a third of a second
    from threat_planner.core.network.partition import Network

__all__ = ['PlanResult', 'detection_of']


@dataclass
class PlanResult:
    """Everything a plan produced.

    Attributes:
        method: Method used.
        w: Threat weight used.
        network: The incentre network.
        entry: Entry node id (0-based).
        exit: Exit node id (0-based).
        node_sequence: Dijkstra node ids from entry to exit.
        initial_path: Start, the Dijkstra nodes, goal, (m, 3) [m].
        smoothed_path: Rest state of the mass-spring chain, (n+1, 3) [m]; None when
            'best' went straight to the direct minimisation.
        path: Final path, (n+1, 3) [m].
        initial_cost: Cost of initial_path.
        smoothed_cost: Cost of smoothed_path, or None.
        cost: Cost of the final path.
        k: Spring coefficient of the smoothing that produced the final path.
        angles: Angle check of the final path.
        smoothing_steps: Integration steps of the chosen smoothing.
        smoothing_converged: Whether that integration met its stopping rule.
        candidates: Final J for each (entry, exit) pair tried (Case 1), or empty.
        k_sweep: Final J (inf if infeasible) for each k tried (Case 3), or empty.
        seed: Which start the final path grew from ('route i' or 'straight line').
        edge_cutoff: Cut-off radius of the edge costs [m], None if exact.
        timings_ms: Wall time per stage [ms].
        limits: Physical flight limits in force (method 'best').
        limit_check: The final path's climb, dive, turn radius and altitude against them.
        warm: Whether the plan was warm-started from a previous one (see core/methods/warm.py).
        warm_note: Why a warm start was used or refused ('' for a cold plan).
        basin_margin: Relative J gap between the best and second-best screened basin.
        problem: (threats, start, goal, box, config) planned, kept for warm starts.
        clearance: Smallest margins of the final path to the zones and the terrain
            floor (an ``airspace.Clearance``), or None without an airspace.
        speed_mps: Cruise speed the path is timed at [m/s] (the setting's; it shaped
            nothing, unless cost_model is 'detection').
        cost_model: The cost the plan minimised: 'paper' (J) or 'detection'.
        detection_model: The radar model :attr:`detection` is reported under.
        masking: The terrain that hides the UAV from the radars, or None.
        objective: The minimised w H + (1 - w) L / L_0 of a 'detection' plan, else None.
        detection_status: A 'detection' plan's bound on P_detect: '' (no bound), 'met'
            or why it is not.
    """

    method: str
    w: float
    network: Network
    entry: int
    exit: int
    node_sequence: list[int]
    initial_path: NDArray
    smoothed_path: NDArray | None
    path: NDArray
    initial_cost: Cost
    smoothed_cost: Cost | None
    cost: Cost
    k: float
    angles: AngleCheck
    smoothing_steps: int
    smoothing_converged: bool
    candidates: dict[tuple[int, int], float] = field(default_factory=dict)
    k_sweep: dict[float, float] = field(default_factory=dict)
    seed: str = 'route 0'
    edge_cutoff: float | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    limits: FlightLimits = field(default_factory=FlightLimits)
    limit_check: LimitCheck | None = None
    warm: bool = False
    warm_note: str = ''
    basin_margin: float = float('inf')
    problem: tuple[ThreatField, NDArray, NDArray, Box, object] | None = None
    # airspace hook (issue 12): margins of the final path, None without an airspace.
    clearance: 'Clearance | None' = None  # noqa: F821
    speed_mps: float = PLANNER_SETTINGS['speed_mps'].default
    # detection (issue 43): every plan reports its P_detect under the configured model.
    cost_model: str = 'paper'
    detection_model: DetectionModel | None = None
    masking: object = None
    objective: float | None = None
    detection_status: str = ''
    # Not an init field, so dataclasses.replace (a result with another path: the
    # published in-flight trajectory, a path turned onto a heading) never carries it over.
    _detection: DetectionReport | None = field(default=None, init=False, repr=False,
                                               compare=False)

    @property
    def detection(self) -> DetectionReport:
        """P_detect, H and each threat's share of the final path (computed once, exact)."""
        if self._detection is None:
            threats = self.problem[0] if self.problem is not None else None
            model = self.detection_model or DetectionModel(speed_mps=self.speed_mps)
            if threats is None:
                raise ValueError('detection: the plan keeps no threats to report it under')
            self._detection = detection_of(self.path, threats, model, self.masking)
        return self._detection

    @property
    def times(self) -> NDArray:
        """Time over each point of ``path`` at ``speed_mps``, 0 at the start, (n+1,) [s]."""
        return point_times(self.path, self.speed_mps)

    @property
    def eta_s(self) -> float:
        """Flight time from start to goal along ``path`` at ``speed_mps`` [s]."""
        times = self.times
        return float(times[-1]) if len(times) else 0.0

    @property
    def feasible(self) -> bool:
        """Final path meets the method's limits.

        'best' is held to the physical limits (climb, dive, turn radius, altitude);
        'paper' and 'improved' to the paper's per-vertex pitch and turn angles.
        """
        if self.method == 'best' and self.limit_check is not None:
            return self.limit_check.feasible
        return self.angles.feasible

    def summary(self) -> dict:
        """JSON-ready summary in the command line's ``--json`` layout."""
        times = self.times
        return {
            'method': self.method,
            'w': self.w,
            'speed_mps': self.speed_mps,
            'initial_path': self.initial_path.tolist(),
            'path': self.path.tolist(),
            # Trajectory (issue 44): the time over each path point [s], 0 at the start.
            't': times.tolist(),
            'eta_s': float(times[-1]) if len(times) else 0.0,
            'cost': {'initial': self.initial_cost.as_dict(),
                     'smoothed': None if self.smoothed_cost is None
                     else self.smoothed_cost.as_dict(),
                     'final': self.cost.as_dict()},
            'network': {'nodes': self.network.n_nodes, 'edges': self.network.n_edges},
            'entry': self.entry,
            'exit': self.exit,
            'node_sequence': self.node_sequence,
            # 'best' minimises J directly: no spring, no k (null rather than NaN in JSON).
            'k': self.k if np.isfinite(self.k) else None,
            'seed': self.seed,
            'feasible': self.feasible,
            'angles': {'max_pitch_deg': self.angles.max_pitch_deg,
                       'max_turn_deg': self.angles.max_turn_deg,
                       'pitch_ok': self.angles.pitch_ok, 'turn_ok': self.angles.turn_ok},
            'smoothing': {'steps': self.smoothing_steps,
                          'converged': self.smoothing_converged},
            'edge_cutoff_m': self.edge_cutoff,
            'limits': self.limits.as_dict(),
            'path_limits': None if self.limit_check is None else self.limit_check.as_dict(),
            'worst_violation': None if self.limit_check is None else self.limit_check.worst,
            'warm': self.warm,
            'timings_ms': self.timings_ms,
            **({} if self.clearance is None else {'clearance': self.clearance.as_dict()}),
            'cost_model': self.cost_model,
            'detection': {**self.detection.as_dict(),
                          **({} if self.objective is None else {'objective': self.objective}),
                          **({'status': self.detection_status}
                             if self.detection_status else {})},
        }


def detection_of(points: NDArray, threats: ThreatField, model: DetectionModel,
                 masking: object = None) -> DetectionReport:
    """Exact cumulative detection of a path, over the parts each radar sees."""
    pieces = None
    if masking is not None:
        from threat_planner.core.cost.masking import visible_pieces
        pieces = visible_pieces(points, threats.positions, masking)
    return path_hazard(points, threats.positions, threats.intensities, model, pieces)
