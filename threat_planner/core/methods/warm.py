"""Warm starts: replan from the previous plan's path after a small change.

A replan is warm when, against the previous :class:`~.result.PlanResult`, the settings,
box, goal and intensities are the same, every threat moved by at most WARM_THREAT_SHIFT of
the box diagonal, and the new start lies within WARM_START_SHIFT of the previous path
(a vehicle flying it). The partition, edge costs, route search and basin screening are
then skipped: they depend only on the threats, which barely moved, and their answer was
the previous path's basin. The previous path from the point nearest the new start is
refined under the limits (as it is when the start is on its first segment: resampled
evenly, its corners broke the turn radius). Rule that guards "no worse than a cold plan"
and is the tie rule of issue 28 (a replan keeps the previous plan's basin unless the move
could overturn its lead): the warm start is refused (cold plan) when the previous plan's
basin led the next by less than WARM_BASIN_MARGIN in J times the largest threat move over
WARM_THREAT_SHIFT of the diagonal (a 1 % move could swap basins 2 % apart), or by nothing;
up to a move of WARM_TIE_SHIFT of the diagonal (1.7 mm in a 100 m box) the previous basin
is kept whatever the lead (basins it could swap with tie within 0.1 %). That lead is the
screening's where the flight limits did not bind; where they did, the slope-held
screening's, capped by the lead over the next distinct basin refined under all the
limits. The warm result is dropped for a cold plan when it breaks a limit the previous
plan met. Crowded fields (threat reach at least the spacing,
:func:`.optimisation.is_crowded`) always plan cold. The cruise speed is not among the
settings compared: it times a path and shapes none (``PlannerConfig.plans_like``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from threat_planner.core._vector import vector_length
from threat_planner.core.optimise.optimisation import is_crowded
from threat_planner.core.optimise.smoothing import resample
from threat_planner.core.world.threats import Box, ThreatField

__all__ = ['WARM_BASIN_MARGIN', 'WARM_START_SHIFT', 'WARM_THREAT_SHIFT', 'WARM_TIE_SHIFT',
           'warm_path']

#: Largest threat displacement of a warm replan, as a fraction of the box diagonal.
WARM_THREAT_SHIFT = 0.01
#: Largest distance of the new start from the previous path, fraction of the diagonal.
WARM_START_SHIFT = 0.01
#: Smallest lead of the previous best basin over the second for a warm replan after a
#: move of WARM_THREAT_SHIFT (in proportion below).
WARM_BASIN_MARGIN = 0.02
#: Up to this largest threat move, as a fraction of the diagonal, the previous basin is
#: kept even with no lead known: J moves by ~4 move / distance to the path there (a few
#: 1e-4), so basins it could swap with were within 0.1 % of each other, a tie, settled for
#: the previous plan (test_stable_plans' seed 84: with no lead known the replan went cold
#: and came out 0.7 % above after a 1 um move).
WARM_TIE_SHIFT = 1e-5


def _project(path: NDArray, point: NDArray) -> tuple[int, NDArray, float]:
    """Segment index, foot point and distance of point's projection onto a polyline."""
    a, b = path[:-1], path[1:]
    d = b - a
    l2 = np.einsum('ik,ik->i', d, d)
    t = np.clip(np.einsum('ik,ik->i', point - a, d) / np.where(l2 > 0, l2, 1.0), 0.0, 1.0)
    foot = a + t[:, None] * d
    dist = np.linalg.norm(foot - point, axis=1)
    k = int(np.argmin(dist))
    return k, foot[k], float(dist[k])


def warm_path(previous: object, threats: ThreatField, s: NDArray, t: NDArray, box: Box,
              config: object) -> tuple[NDArray | None, str]:
    """Return the starting path of a warm replan, or None and why it must be cold.

    Parameters
    ----------
    previous : PlanResult
        The previous plan.
    threats : ThreatField
        The threats now.
    s, t : ndarray
        Start and goal now, (3,) [m].
    box : Box
        Flight box now.
    config : PlannerConfig
        Settings now.

    Returns
    -------
    tuple
        ``(path (n+1, 3) or None, note)``.

    """
    if previous.problem is None:
        return None, 'cold: the previous result holds no problem'
    p_threats, _, p_goal, p_box, p_config = previous.problem
    if config.method != 'best' or not config.optimise:
        return None, "cold: warm starts are for method 'best' with optimise"
    if not config.plans_like(p_config):
        return None, 'cold: settings changed'
    diag = box.diagonal
    if not (np.array_equal(box.lo, p_box.lo) and np.array_equal(box.hi, p_box.hi)):
        return None, 'cold: bounds changed'
    if vector_length(t - p_goal) > 1e-9 * diag:
        return None, 'cold: goal moved'
    if len(threats) != len(p_threats) or not np.allclose(
            threats.intensities, p_threats.intensities, rtol=1e-9, atol=0.0):
        return None, 'cold: threats added, removed or changed intensity'
    shift = 0.0
    if len(threats):
        shift = float(np.max(np.linalg.norm(threats.positions - p_threats.positions, axis=1)))
        if shift > WARM_THREAT_SHIFT * diag:
            return None, f'cold: a threat moved {shift:.3g} m'
    if is_crowded(threats, box):
        # Measured on a random 1,000-threat field in a 100 m box: a 0.5 m start move
        # changed the cold optimum by up to 20 %, and a warm replan came out 33 % above it.
        return None, 'cold: crowded field (threat reach >= spacing), its basins shift'
    tie = shift <= WARM_TIE_SHIFT * diag
    if previous.basin_margin == 0.0 and not tie:
        return None, 'cold: the flight limits bound the previous plan, no second basin to compare'
    if previous.basin_margin < WARM_BASIN_MARGIN * shift / (WARM_THREAT_SHIFT * diag) and not tie:
        return None, (f'cold: basins within {100 * previous.basin_margin:.2g} % of each other '
                      f'(a threat moved {shift:.3g} m)')
    k, _, dist = _project(previous.path, s)
    if dist > WARM_START_SHIFT * diag:
        return None, f'cold: start {dist:.3g} m off the previous path'
    if k == 0 and len(previous.path) == config.n_points + 1:
        return np.vstack([s, previous.path[1:]]), 'warm'
    path = np.vstack([s, previous.path[k + 1:]])
    return resample(path, config.n_points), 'warm'
