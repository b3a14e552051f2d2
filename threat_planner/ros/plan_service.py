"""The node's ``plan_path`` service (nav_msgs/srv/GetPlan): a plan on request.

A request is planned against the node's current threat picture and settings with the
request's start and goal, checked exactly as the ``start`` and ``goal_pose`` topics are
(:func:`threat_planner.ros.inputs.accept` on a copy of the state), and never touches the
node's latched state or outputs. Requests are served first come, first served by a thread
of their own, separate from the topic planner's worker, so a request is answered while a
topic-triggered plan runs; at most :data:`QUEUE_BOUND` requests wait, a request beyond
that is answered at once with an empty path. The service callback is a coroutine that
awaits the answer, so the executor keeps spinning while a request is planned. A refused or
failed request gets an empty path and one WARN log line with the reason.

Threats that move (a cloud's ``vx vy vz``) are planned in time from the request's t0, the
goal's stamp (the cloud's own time when the goal is unstamped), as the node plans them
(:mod:`threat_planner.ros.flight_plan`). The request carries no velocity: a GetPlan plan
starts at rest, and ignores the vehicle's odometry.
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Callable, Optional

from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.task import Future

from threat_planner.core.trajectory import point_times
from threat_planner.errors import InputError, PlanningError
from threat_planner.ros.conversions import path_to_msg, stamp_to_ns
from threat_planner.ros.flight import moving, timeline_of
from threat_planner.ros.inputs import accept, InputState

__all__ = ['PLAN_SERVICE', 'PlanService', 'QUEUE_BOUND', 'plan_on_request']

PLAN_SERVICE = 'plan_path'
#: Requests that may wait for the one being planned; one more is refused at once.
QUEUE_BOUND = 8


def plan_on_request(state: InputState, request: GetPlan.Request) -> tuple[Path, str]:
    """Plan one GetPlan request against `state`.

    Parameters
    ----------
    state : InputState
        The node's current state (not modified).
    request : GetPlan.Request
        Start and goal (PoseStamped, frame checked against parameter ``frame_id``).

    Returns
    -------
    tuple of (Path, str)
        The final path (empty on failure) and the reason of a failure ('' on success).
        Its header has the goal's stamp, t0; pose k is stamped t0 plus the time over
        point k at ``speed_mps``.

    """
    frame_id = state.settings.frame_id
    try:
        if state.threats is None:
            raise InputError('no threat picture received yet')
        s = accept(state, 'start', request.start)
        s = accept(s, 'goal_pose', request.goal)
        from threat_planner.core.planner import plan  # loaded by PlanService._loop
        cfg = s.settings.config
        if moving(s.velocities):
            from threat_planner.core.flight.replan import plan_in_time
            t0_ns = stamp_to_ns(request.goal.header.stamp) or s.threats_stamp_ns
            air = s.airspace
            timed = plan_in_time(timeline_of(s.threats, s.velocities, s.threats_stamp_ns, t0_ns),
                                 s.start, s.goal, s.settings.box, cfg, cfg.speed_mps,
                                 zones=() if air is None else tuple(air.zones),
                                 terrain=None if air is None else air.terrain)
            points, times = timed.points, timed.times
        else:
            points = plan(s.threats, s.start, s.goal, s.settings.box, cfg,
                          airspace=s.airspace).path
            times = point_times(points, cfg.speed_mps)
    except (InputError, PlanningError) as exc:
        return _empty_path(frame_id, request), str(exc)
    except Exception as exc:  # noqa: B902 - a planner bug must not kill the service
        return _empty_path(frame_id, request), f'planner failed: {type(exc).__name__}: {exc}'
    # A trajectory from the requester's t0, the goal's stamp: pose k at t0 + t_k (issue 44).
    return path_to_msg(points, frame_id, request.goal.header.stamp, times), ''


def _empty_path(frame_id: str, request: GetPlan.Request) -> Path:
    msg = Path()
    msg.header.frame_id = frame_id
    msg.header.stamp = request.goal.header.stamp
    return msg


class PlanService:
    """The ``plan_path`` service of a planner node, with its own planning thread.

    Parameters
    ----------
    node : rclpy.node.Node
        The node that offers the service.
    current_state : Callable[[], InputState]
        Returns the node's state at the time a request is taken.

    """

    def __init__(self, node: Node, current_state: Callable[[], InputState]) -> None:
        self._node = node
        self._current_state = current_state
        self._jobs: queue.Queue = queue.Queue(maxsize=QUEUE_BOUND)
        self._count = 0
        # Done when the latest queued request has been answered: each answer waits for the
        # one before it, since the executor resumes ready coroutines newest first.
        self._answered: Future = Future()
        self._answered.set_result(None)
        # Wakes the executor when an answer is ready, so the awaiting callback resumes.
        self._wake = node.create_guard_condition(lambda: None)
        # Reentrant: a mutually exclusive group stays held while a callback's coroutine
        # awaits, so the executor would take no further request until the first is answered
        # (requests waited in the middleware, unbounded, and none was ever refused). Order
        # is kept: one executor thread takes requests in arrival order into the queue.
        self._service = node.create_service(
            GetPlan, PLAN_SERVICE, self._serve, callback_group=ReentrantCallbackGroup())
        self._thread = threading.Thread(target=self._loop, name='threat_planner_service',
                                        daemon=True)
        self._thread.start()

    @property
    def name(self) -> str:
        """The service's resolved name."""
        return self._service.srv_name

    async def _serve(self, request: GetPlan.Request, response: GetPlan.Response
                     ) -> GetPlan.Response:
        self._count += 1
        number = self._count
        answer: Future = Future()
        try:
            self._jobs.put_nowait((number, self._current_state(), request, answer))
        except queue.Full:
            reason = f'{QUEUE_BOUND} requests already waiting'
            self._node.get_logger().warning(f'{PLAN_SERVICE} request #{number} refused: '
                                            f'{reason}')
            response.plan = _empty_path(self._current_state().settings.frame_id, request)
            return response
        previous, answered = self._answered, Future()
        self._answered = answered
        response.plan = await answer
        await previous
        # The executor sends this response before it resumes the next coroutine.
        answered.set_result(None)
        return response

    def _loop(self) -> None:
        # The planner (and scipy.spatial, a third of a second) loads here, beside the node's
        # start, not in the first request: the node's own topic plans run in a child.
        import threat_planner.core.planner  # noqa: F401
        while True:
            job = self._jobs.get()
            if job is None:
                return
            number, state, request, answer = job
            t0 = time.perf_counter()
            path, reason = plan_on_request(state, request)
            ms = 1e3 * (time.perf_counter() - t0)
            log = self._node.get_logger()
            if reason:
                log.warning(f'{PLAN_SERVICE} request #{number} failed: {reason}')
            else:
                log.info(f'{PLAN_SERVICE} request #{number}: {len(path.poses)} poses in '
                         f'{ms:.0f} ms')
            answer.set_result(path)
            try:
                self._wake.trigger()
            except Exception:  # noqa: B902 - the node may be torn down meanwhile
                pass

    def close(self, timeout: Optional[float] = 0.1) -> None:
        """Destroy the service and end the planning thread (a running plan is dropped)."""
        # Waiting requests are dropped; their callers time out as for a vanished server.
        while True:
            try:
                self._jobs.get_nowait()
            except queue.Empty:
                break
        self._jobs.put(None)
        self._node.destroy_service(self._service)
        self._node.destroy_guard_condition(self._wake)
        self._thread.join(timeout)
