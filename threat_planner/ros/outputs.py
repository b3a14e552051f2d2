"""How a plan becomes the node's outputs: one place, used by the node and by ``plan --record``.

:func:`run_plan` plans one :class:`PlanRequest` and hands its outputs over in phases, as
soon as each is ready: ``'paths'`` (``initial_path`` and ``path``), then ``'done'``
(``network`` markers and ``plan_info``), or ``'error'`` (an ERROR ``plan_info``); a caller
that may stop the plan early also gets the network route as soon as the search has it, and
publishes it with :func:`timeout_outcome` (phase ``'timeout'``) when it stops the plan.
:func:`outcome_messages` gives the (topic, message) pairs of a phase in publishing order.

The paths are trajectories (issue 44): the header stamp is the plan's t0, the node clock
when the input that asked for the plan arrived (``PlanRequest.received_ns``, the node's
own clock, sim time included, which a plan process cannot read), and pose k is stamped
t0 + t_k, the time over point k at the cruise speed ``speed_mps``
(:func:`threat_planner.core.trajectory.point_times`). ``plan_info`` gives t0 as
``t0_ns``, which is how a reader pairs the paths with the input they answer. A request
that knows the vehicle (``odom``) or moving threats is planned in time
(:mod:`threat_planner.ros.flight_plan`): its path is stamped with the times of the
trajectory planned, a replan in flight's with those of the splice.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import Callable, Mapping, Optional

from builtin_interfaces.msg import Time
from nav_msgs.msg import Path
from numpy.typing import NDArray
from visualization_msgs.msg import MarkerArray

from threat_planner.core.cost.closed_form import Cost
from threat_planner.core.result import PlanResult
from threat_planner.core.trajectory import point_times
from threat_planner.core.world.airspace import Airspace
from threat_planner.core.world.threats import Box, ThreatField
from threat_planner.errors import InputError, PlanningError
from threat_planner.ros.conversions import network_markers, ns_to_stamp, path_to_msg, Vehicle
from threat_planner.ros.conversions.markers import airspace_markers
from threat_planner.ros.parameters import NodeSettings
from threat_planner.ros.plan_info import (input_values, plan_done_info, plan_error_info,
                                          plan_timeout_info)

__all__ = ['PlanOutcome', 'PlanRequest', 'input_values', 'outcome_messages', 'plan_done_info',
           'plan_error_info', 'plan_markers', 'plan_timeout_info', 'run_plan',
           'timeout_outcome']


@dataclass(frozen=True)
class PlanRequest:
    """A snapshot of everything a plan needs, tagged with the input it answers."""

    seq: int
    source: str
    stamp: Time
    received_ns: int
    threats: ThreatField
    start: NDArray
    goal: NDArray
    settings: NodeSettings
    airspace: Optional[Airspace] = None
    # flight (issue 44; ros/flight.py, ros/flight_plan.py): threat velocities (N, 3) [m/s]
    # and when the positions hold [ns]; the vehicle; the trajectory flown and the
    # vehicle's arc length on it at t0 [m], for a replan in flight; why it was asked for.
    velocities: Optional[NDArray] = None
    threats_t_ns: int = 0
    vehicle: Optional[Vehicle] = None
    flown: Optional[NDArray] = None
    s_now: float = 0.0
    reason: str = ''


@dataclass
class PlanOutcome:
    """A plan's result and messages, handed from the worker to the publisher."""

    request: PlanRequest
    result: Optional[PlanResult] = None
    initial_path: Optional[Path] = None
    path: Optional[Path] = None
    network: Optional[MarkerArray] = None   # or its CDR bytes, from the plan process
    network_error: Optional[str] = None
    error: Optional[str] = None
    exception: Optional[Exception] = None
    #: The best path so far of a plan not finished yet (the network route) and its cost.
    best_so_far: Optional[Path] = None
    best_so_far_cost: Optional[Cost] = None
    best_so_far_points: int = 0
    best_so_far_eta_s: float = 0.0
    queue_ms: float = 0.0
    plan_ms: float = 0.0
    messages_ms: float = 0.0
    #: A timed plan's: the static result planned (the next warm start) and its values.
    static: Optional[PlanResult] = None
    values: Optional[dict] = None


def run_plan(request: PlanRequest, hand_over: Callable[[str, PlanOutcome], None],
             now_ns: Callable[[], int],
             progress: Optional[Callable[[int, int], None]] = None,
             early: Optional[Callable[[PlanOutcome], None]] = None,
             warm_start: Optional[PlanResult] = None) -> PlanOutcome:
    """Plan `request` and build its messages, handing each phase over when it is ready.

    Parameters
    ----------
    request : PlanRequest
        What to plan.
    hand_over : Callable[[str, PlanOutcome], None]
        Called with ``'paths'`` then ``'done'``, or with ``'error'``.
    now_ns : Callable[[], int]
        The clock the request's ``received_ns`` was read from [ns].
    progress : callable, optional
        ``progress(done, total)`` for long sweeps.
    early : callable, optional
        Called with an outcome holding ``best_so_far`` (the network route) as soon as the
        search has found it, before the smoothing and optimisation.
    warm_start : PlanResult, optional
        The previous plan, to replan from after a small change (core/methods/warm.py decides).

    Returns
    -------
    PlanOutcome
        The outcome (also handed over).

    """
    outcome = PlanOutcome(request)
    t0 = time.perf_counter()
    outcome.queue_ms = max(0.0, 1e-6 * (now_ns() - request.received_ns))
    s = request.settings

    start = ns_to_stamp(request.received_ns)   # the trajectory's t0

    def timed(points) -> Path:
        return path_to_msg(points, s.frame_id, start, point_times(points, s.config.speed_mps))

    def on_initial(points, cost: Cost) -> None:
        partial = PlanOutcome(request, queue_ms=outcome.queue_ms,
                              plan_ms=1e3 * (time.perf_counter() - t0))
        partial.best_so_far = timed(points)
        partial.best_so_far_cost, partial.best_so_far_points = cost, len(points)
        partial.best_so_far_eta_s = float(point_times(points, s.config.speed_mps)[-1])
        early(partial)

    # Here, not at the top: the node's own process imports this module but plans in a
    # child, which imports the planner (and its scipy.spatial) before it reports ready.
    from threat_planner.core.planner import plan
    from threat_planner.ros.flight_plan import is_timed, plan_flight
    try:
        if is_timed(request):
            # No best path so far: a timed-out plan in flight keeps the last good one.
            answer = plan_flight(request, warm_start)
            result, outcome.static, outcome.values = answer.result, answer.static, \
                answer.values
            outcome.initial_path = path_to_msg(result.initial_path, s.frame_id, start,
                                               answer.initial_times)
            outcome.path = path_to_msg(answer.points, s.frame_id, start, answer.times)
        else:
            result = plan(request.threats, request.start, request.goal, s.box, s.config,
                          progress=progress, on_initial=None if early is None else on_initial,
                          airspace=request.airspace, warm_start=warm_start)
            outcome.initial_path = timed(result.initial_path)
            outcome.path = timed(result.path)
        t1 = time.perf_counter()
        outcome.plan_ms = 1e3 * (t1 - t0)
        outcome.result = result
    except (InputError, PlanningError) as exc:
        outcome.error, outcome.exception = str(exc), exc
    except Exception as exc:  # noqa: B902 - a planner bug must not kill the worker
        outcome.error = f'planner failed: {type(exc).__name__}: {exc}'
        outcome.exception = exc
    if outcome.error is not None:
        hand_over('error', outcome)
        return outcome
    # The paths go out before the markers are built: for 1000 threats the MarkerArray
    # takes ~0.1 s, which a path follower should not wait for.
    hand_over('paths', outcome)
    try:
        outcome.network = plan_markers(result, request.threats, s.box, s.frame_id,
                                       request.stamp, request.airspace)
    except Exception as exc:  # noqa: B902 - a drawing bug must not lose the plan
        outcome.network_error = f'{type(exc).__name__}: {exc}'
    outcome.messages_ms = 1e3 * (time.perf_counter() - t1)
    hand_over('done', outcome)
    return outcome


def outcome_messages(phase: str, outcome: PlanOutcome,
                     values: Mapping[str, object]) -> list[tuple[str, object]]:
    """Return the (relative topic, message) pairs of one phase, in publishing order.

    Parameters
    ----------
    phase : str
        ``'paths'``, ``'done'`` or ``'error'``.
    outcome : PlanOutcome
        The plan.
    values : Mapping[str, object]
        The input's ``plan_info`` values (:func:`input_values`), for ``'done'``/``'error'``.

    Returns
    -------
    list of (str, message)
        What to publish.

    """
    req = outcome.request
    if phase == 'timeout':
        return [('initial_path', outcome.best_so_far), ('path', outcome.best_so_far),
                ('plan_info', plan_timeout_info(values, outcome))]
    if phase == 'paths':
        return [('initial_path', outcome.initial_path), ('path', outcome.path)]
    if phase == 'error':
        return [('plan_info', plan_error_info(values, req.seq, req.source, outcome.error,
                                              req.stamp))]
    info = plan_done_info(values, outcome.result, len(req.threats), req.stamp,
                          outcome.queue_ms, outcome.plan_ms, outcome.messages_ms,
                          outcome.network_error, t0_ns=req.received_ns, extra=outcome.values)
    network = [] if outcome.network is None else [('network', outcome.network)]
    return network + [('plan_info', info)]


def timeout_outcome(request: PlanRequest, best_so_far: Optional[PlanOutcome],
                    running_s: float, limit_s: float) -> tuple[str, PlanOutcome]:
    """Return the phase and outcome of a plan stopped by ``max_plan_time_s``.

    Parameters
    ----------
    request : PlanRequest
        The plan stopped.
    best_so_far : PlanOutcome or None
        The early outcome with the network route, if the search had finished.
    running_s, limit_s : float
        How long the plan ran and its limit [s].

    Returns
    -------
    tuple of (str, PlanOutcome)
        ``'timeout'`` with the best path so far to publish, or ``'error'`` without one.

    """
    error = f'timed out after {running_s:.1f} s (max_plan_time_s={limit_s:g})'
    if best_so_far is None:
        return 'error', PlanOutcome(request, plan_ms=1e3 * running_s,
                                    error=error + '; the previous plan stays latched')
    best_so_far.plan_ms = 1e3 * running_s
    best_so_far.error = (error + '; published the best path so far: the network route, '
                         'before smoothing and optimisation')
    return 'timeout', best_so_far


def plan_markers(result: PlanResult, threats: ThreatField, box: Box, frame_id: str,
                 stamp: Time, airspace: Optional[Airspace] = None) -> MarkerArray:
    """Draw a plan's threats, mesh, network, paths and airspace, sized to the flight box.

    Parameters
    ----------
    result : PlanResult
        The plan.
    threats : ThreatField
        The threats it was planned through.
    box : Box
        Flight box (sets the marker sizes).
    frame_id : str
        Frame of the markers.
    stamp : builtin_interfaces.msg.Time
        Stamp of the markers (the input's).
    airspace : Airspace, optional
        Zones and terrain planned in; drawn in namespaces ``zones`` and ``terrain``.

    Returns
    -------
    MarkerArray
        What the node publishes on ``network``.

    """
    scale = box.diagonal / math.sqrt(3.0) / 100.0
    net = result.network
    markers = network_markers(
        threats.positions, threats.intensities,
        vertices=net.vertices, delaunay_edges=net.delaunay_edges(), nodes=net.nodes,
        network_edges=net.edges, initial_path=result.initial_path,
        path=result.path, frame_id=frame_id, stamp=stamp,
        threat_diameter=4.0 * scale, node_diameter=scale, line_width=0.2 * scale)
    if airspace is not None:
        markers.markers.extend(airspace_markers(airspace, frame_id, stamp, 0.2 * scale))
    return markers
