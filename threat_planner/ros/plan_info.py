"""The ``plan_info`` of a plan (done, failed, timed out) and of the input it answers.

Split from :mod:`threat_planner.ros.outputs`, which re-exports every name here.
"""

from __future__ import annotations

from typing import Mapping, Optional

import numpy as np

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray

from threat_planner.core.result import PlanResult
from threat_planner.ros.conversions import plan_info_msg, stamp_to_ns

__all__ = ['detection_top', 'detection_values', 'input_values', 'plan_done_info',
           'plan_error_info', 'plan_timeout_info']

#: Threats named in ``detection_top``: the largest shares of H.
DETECTION_TOP = 3


def plan_error_info(values: Mapping[str, object], seq: int, source: str, error: str,
                    stamp: Time) -> DiagnosticArray:
    """Build the ERROR ``plan_info`` of a plan that failed; its message is the log line."""
    values = dict(values)
    values['error'] = error
    return plan_info_msg('ERROR', f'plan for input #{seq} ({source}) failed: {error}',
                         values, stamp)


def plan_timeout_info(values: Mapping[str, object], outcome) -> DiagnosticArray:
    """Build the WARN ``plan_info`` of a timed-out plan published with its best path so far."""
    req, cost = outcome.request, outcome.best_so_far_cost
    values = dict(values)
    values.update({'error': outcome.error, 'timed_out': True, 'best_so_far': 'initial',
                   'method': req.settings.config.method, 'w': req.settings.config.w,
                   'threats': len(req.threats), 'J': cost.J, 'J_L': cost.J_L,
                   'J_R': cost.J_R, 'path_points': outcome.best_so_far_points,
                   't0_ns': req.received_ns, 'speed_mps': req.settings.config.speed_mps,
                   'eta_s': outcome.best_so_far_eta_s,
                   'queue_ms': outcome.queue_ms, 'plan_wall_ms': outcome.plan_ms})
    message = (f'plan for input #{req.seq} ({req.source}) {outcome.error}; '
               f'J={cost.J:.6g}')
    return plan_info_msg('WARN', message, values, req.stamp)


def input_values(seq: int, source: str, stamp: Time, frame_id: str, received: int,
                 rejected: int, skipped: int, plans: int,
                 odom_rejected: Optional[int] = None) -> dict[str, object]:
    """Return the ``plan_info`` values naming an input and the node's counters.

    Parameters
    ----------
    seq : int
        Input sequence number.
    source : str
        Topic of the input, or ``'parameters'``.
    stamp : builtin_interfaces.msg.Time
        The input's stamp.
    frame_id : str
        Frame of the outputs.
    received, rejected, skipped, plans : int
        Counters of inputs received, rejected and skipped, and of plans completed.
    odom_rejected : int, optional
        Odometry messages refused (a node's; included when given).

    Returns
    -------
    dict[str, object]
        Keys in ``plan_info`` order.

    """
    values = {
        'input_seq': seq,
        'input_source': source,
        'input_stamp_ns': stamp_to_ns(stamp),
        'frame_id': frame_id,
        'inputs_received': received,
        'inputs_rejected': rejected,
        'inputs_skipped': skipped,
        'plans_completed': plans,
    }
    if odom_rejected is not None:
        values['odom_rejected'] = odom_rejected
    return values


def plan_done_info(values: Mapping[str, object], result: PlanResult, n_threats: int,
                   stamp: Time, queue_ms: float, plan_ms: float, messages_ms: float,
                   network_error: Optional[str] = None,
                   t0_ns: Optional[int] = None,
                   extra: Optional[Mapping[str, object]] = None) -> DiagnosticArray:
    """Build the ``plan_info`` of a finished plan (OK, or WARN if an angle limit is broken).

    Parameters
    ----------
    values : Mapping[str, object]
        The input's values (:func:`input_values`); the result's are appended.
    result : PlanResult
        The plan.
    n_threats : int
        Threats planned through.
    stamp : builtin_interfaces.msg.Time
        The input's stamp.
    queue_ms, plan_ms, messages_ms : float
        Wait before planning, planning and marker drawing times [ms].
    network_error : str, optional
        Why the markers could not be drawn.
    t0_ns : int, optional
        The paths' header stamp, the trajectory's t0 [ns], given as ``t0_ns``.
    extra : Mapping[str, object], optional
        A timed plan's values (:mod:`threat_planner.ros.flight_plan`), appended.

    Returns
    -------
    DiagnosticArray
        The message; its status message is the node's log line.

    """
    values = dict(values)
    values.update(_result_values(result, n_threats))
    if t0_ns is not None:
        values['t0_ns'] = int(t0_ns)
    values['queue_ms'] = queue_ms
    values['plan_wall_ms'] = plan_ms
    values['messages_ms'] = messages_ms
    if network_error is not None:
        values['network_error'] = network_error
    values.update(extra or {})
    status = 'OK' if result.feasible else 'WARN'
    message = (f'plan for input #{values["input_seq"]} ({values["input_source"]}): '
               f'J={result.cost.J:.6g} through {n_threats} threats in {plan_ms:.0f} ms'
               + ('' if result.feasible else '; violates a flight limit'))
    return plan_info_msg(status, message, values, stamp)


def _result_values(result: PlanResult, n_threats: int) -> dict[str, object]:
    values: dict[str, object] = {
        'method': result.method,
        'w': result.w,
        'threats': n_threats,
        'J': result.cost.J,
        'J_L': result.cost.J_L,
        'J_R': result.cost.J_R,
        'initial_J': result.initial_cost.J,
        'initial_J_L': result.initial_cost.J_L,
        'initial_J_R': result.initial_cost.J_R,
        'nodes': result.network.n_nodes,
        'edges': result.network.n_edges,
        'entry': result.entry,
        'exit': result.exit,
        'k': result.k,
        'feasible': result.feasible,
        'max_pitch_deg': result.angles.max_pitch_deg,
        'max_turn_deg': result.angles.max_turn_deg,
        'path_points': len(result.path),
        'initial_path_points': len(result.initial_path),
        # Trajectory (issue 44): the path's poses are stamped t0 + t_k at this speed.
        'speed_mps': result.speed_mps,
        'eta_s': result.eta_s,
    }
    # Physical limits (method 'best'): those in force, the path's own values, the worst
    # violation ('' when feasible). Infinities (a straight path's radius) print as inf.
    for key, limit in result.limits.as_dict().items():
        values[f'limit_{key}'] = limit
    check = result.limit_check
    if check is not None:
        values['path_climb_deg'] = check.climb_deg
        values['path_dive_deg'] = check.dive_deg
        values['path_min_turn_radius_m'] = check.min_turn_radius_m
        values['path_min_altitude_m'] = check.min_altitude_m
        values['limits_feasible'] = check.feasible
        values['worst_violation'] = '' if check.worst is None else (
            f'{check.worst} {check.violations[check.worst]:.6g}')
    values['start'] = 'warm' if getattr(result, 'warm', False) else 'cold'
    if result.clearance is not None:   # airspace (issue 12): smallest margins [m]
        c = result.clearance
        values['clearance_zones_m'] = c.zones_m
        values['clearance_terrain_m'] = c.terrain_m
    values.update(detection_values(result))
    values.update(result.timings_ms)
    return values


def detection_top(per_threat, n: int = DETECTION_TOP) -> str:
    """Return the `n` largest shares H_i / H as ``'index:share'``, largest first, comma-separated.

    ``''`` when H is 0 (no threats, or none seen).
    """
    per = np.asarray(per_threat, float).ravel()
    total = float(per.sum())
    if not (total > 0.0 and np.isfinite(total)):
        return ''
    order = np.argsort(-per, kind='stable')[:n]
    return ','.join(f'{int(i)}:{per[i] / total:.4g}' for i in order)


def detection_values(result: PlanResult) -> dict[str, object]:
    """``plan_info``'s detection keys of a plan (issue 43): every plan reports them.

    ``cost_model``, ``P_detect``, ``H``, ``detection_top`` (:func:`detection_top`), and
    ``detection_objective`` (the minimised w H + (1 - w) L / L_0) / ``detection_status``
    when the plan has them; ``{'cost_model': ...}``
    alone for a plan that keeps no threats to report under.
    """
    values: dict[str, object] = {'cost_model': result.cost_model}
    try:
        report = result.detection
    except ValueError:
        return values
    values['P_detect'] = float(report.p_detect)
    values['H'] = float(report.hazard)
    values['detection_top'] = detection_top(report.per_threat)
    if result.objective is not None:
        values['detection_objective'] = float(result.objective)
    if result.detection_status:
        values['detection_status'] = result.detection_status
    return values
