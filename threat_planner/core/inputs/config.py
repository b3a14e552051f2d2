"""PlannerConfig: the planner's settings, with defaults and ranges from :mod:`.settings`."""

from __future__ import annotations

from dataclasses import dataclass, replace

from threat_planner.core.inputs.settings import PLANNER_SETTINGS
from threat_planner.errors import InputError

__all__ = ['PlannerConfig', 'TIMING_FIELDS']

_D = {name: s.default for name, s in PLANNER_SETTINGS.items()}
#: Fields that time a path but never shape it: no stage of the planner reads them.
TIMING_FIELDS = ('speed_mps', 'commit_s')


@dataclass(frozen=True)
class PlannerConfig:
    """Planner settings; every field has a sensible default.

    The meaning, unit and range of every field are declared once in
    :data:`threat_planner.core.inputs.settings.SETTINGS`.

    Attributes:
        w: Threat weight in J = w J_R + (1-w) J_L, 0 < w < 1.
        method: 'paper', 'improved' or 'best'.
        k: Spring coefficient of the smoothing chain.
        auto_k: Sweep k over K_SWEEP for least J (Case 3); 'improved' always does.
        damping: Damping coefficient b between neighbouring masses (eq. 9-10).
        mass: Mass M of each chain point (eq. 14).
        q: Repulsion constant Q (eq. 13).
        n_points: Number of chain segments n (the chain has n+1 points).
        max_pitch_deg: Pitch limit [deg].
        max_turn_deg: Turn (steering) limit between consecutive segments [deg].
        max_climb_deg: Steepest climb of a segment ('best') [deg]; 90 = off.
        max_dive_deg: Steepest dive of a segment ('best') [deg]; 90 = off.
        min_turn_radius_m: Smallest turn radius through 3 consecutive points ('best')
            [m]; 0 = off.
        min_altitude_m: Lowest height above the box floor ('best') [m]; 0 = off.
        speed_mps: Cruise speed [m/s] that times the path (core/trajectory.py); no
            stage of the planner reads it.
        commit_s: Trajectory ahead of the vehicle a replan in flight keeps [s]; no
            stage of the planner reads it.
        cost_model: 'paper' (J) or 'detection' (w H + (1 - w) L / L_0, issue 43).
        max_detection: Bound on P_detect of a 'detection' plan (1 = none): the shortest
            path within it.
        scan_period_s: Radar scan period T [s] of the detection model.
        p_fa: False-alarm probability per scan, 0 < p_fa < 1.
        swerling: Swerling case 0 or 1.
        rcs: RCS model, 'constant S' [m^2] or 'ellipsoid A B C' [m].
        entry_candidates: K nodes tried as entry and as exit (Case 1).
        candidates: How 'improved' picks them: 'spread' (Fig. 11) or 'nearest'.
        network: 'box' (threats and the box surface) or 'threats' (the paper's).
        routes: Distinct network routes screened by 'best' (plus the straight line).
        surface_seeds: Also screen routes over the box's surface lattice ('best' only).
        box_divisions: Intervals per box edge of the auxiliary surface lattice.
        optimise: Run the direct J minimisation ('best' only).
        confine_to_box: Keep the optimised path inside the flight box; False lets the
            direct minimisation leave it (the reference yardstick's setting).
        max_smoothing_steps: Step limit of the chain integration.
    """

    w: float = _D['w']
    method: str = _D['method']
    k: float = _D['k']
    auto_k: bool = _D['auto_k']
    damping: float = _D['damping']
    mass: float = _D['mass']
    q: float = _D['q']
    n_points: int = _D['n_points']
    max_pitch_deg: float = _D['max_pitch_deg']
    max_turn_deg: float = _D['max_turn_deg']
    max_climb_deg: float = _D['max_climb_deg']
    max_dive_deg: float = _D['max_dive_deg']
    min_turn_radius_m: float = _D['min_turn_radius_m']
    min_altitude_m: float = _D['min_altitude_m']
    speed_mps: float = _D['speed_mps']
    commit_s: float = _D['commit_s']
    cost_model: str = _D['cost_model']
    max_detection: float = _D['max_detection']
    scan_period_s: float = _D['scan_period_s']
    p_fa: float = _D['p_fa']
    swerling: int = _D['swerling']
    rcs: str = _D['rcs']
    entry_candidates: int = _D['entry_candidates']
    candidates: str = _D['candidates']
    network: str = _D['network']
    routes: int = _D['routes']
    surface_seeds: bool = _D['surface_seeds']
    box_divisions: int = _D['box_divisions']
    optimise: bool = _D['optimise']
    confine_to_box: bool = _D['confine_to_box']
    max_smoothing_steps: int = _D['max_smoothing_steps']

    def validated(self) -> 'PlannerConfig':
        """Return self after checking every field against its declared range.

        Also the one rule between fields: cost_model 'detection' plans from method 'best'
        (its warm start, limits and optimiser), so it needs method 'best'.

        Raises:
            InputError: naming the field and its bad value.
        """
        for name, setting in PLANNER_SETTINGS.items():
            setting.check(getattr(self, name))
        if self.cost_model == 'detection' and self.method != 'best':
            raise InputError(f"cost_model: detection needs method best, got method "
                             f"{self.method!r} (set method best, or cost_model paper)")
        return self

    def plans_like(self, other: 'PlannerConfig') -> bool:
        """Whether `other` makes the same paths: equal but for the :data:`TIMING_FIELDS`.

        A warm start compares settings with it, so a new cruise speed alone keeps it warm.
        Under cost_model 'detection' the speed weighs the hazard (H = integral of P_d
        ds / (v T)), so there it shapes the path like any other setting.
        """
        timing = tuple(f for f in TIMING_FIELDS
                       if not (f == 'speed_mps' and other.cost_model == 'detection'))
        return replace(self, **{f: getattr(other, f) for f in timing}) == other
