"""Publish a recording's inputs to a running planner node: ``threat-planner replay --live``.

:func:`play_live` publishes the inputs with their recorded timing (scaled by a rate
factor) and sets the recorded parameters through the node's parameter services:
``ros2 bag play`` for this node without ros2cli.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import os
import threading
import time
from typing import Callable, Dict, List, Mapping, Optional, Tuple

from threat_planner.errors import InputError, RecordingError, ThreatPlannerError
from threat_planner.ros.conversions import plan_info_values
from threat_planner.ros.discovery import apply_discovery_profile
from threat_planner.ros.interface import INPUT_TOPICS, LATCHED
from threat_planner.ros.parameters import as_declared
from threat_planner.ros.recording.bagfile import Bag, level_name, PARAMETERS

__all__ = ['LiveResult', 'play_live']


@dataclass
class LiveResult:
    """What :func:`play_live` did.

    Attributes
    ----------
    published : int
        Messages published.
    parameters_set : bool
        Whether the recorded parameters were set on the node.
    parameter_changes : int
        Recorded parameter changes applied.
    duration_s : float
        Time from the first to the last input, plus the wait for the answer [s].
    answers : list of dict
        ``plan_info`` values (plus ``level``) the node published for these inputs.
    last_answered : bool or None
        Whether the node answered the last input (None: nothing to wait for).
    namespace, node_name : str
        Where the inputs went.

    """

    published: int
    parameters_set: bool
    parameter_changes: int
    duration_s: float
    answers: List[Dict[str, str]]
    last_answered: Optional[bool]
    namespace: str
    node_name: str


#: Least gap between inputs on different topics [s]: messages arriving together on several
#: topics are taken by the node's executor in subscription order, not in publishing order,
#: so back-to-back inputs (``plan --record`` writes them microseconds apart: start, goal,
#: zones, terrain, threats) are spaced by this to reach the node in the recorded order.
#: 50 ms was not enough under load: in a fresh clone's suite air_mixed_0's terrain (an
#: Image) reached the node after the threats published 50 ms later, the plan named it, and
#: the replay waited in vain for an answer naming the threats.
TOPIC_SWITCH_GAP_S = 0.2


#: Wait for a latched ``plan_info`` once its publisher is matched [s].
LATCHED_GRACE_S = 0.1


def _normalise_ns(namespace: str) -> str:
    return '/' + namespace.strip('/') if namespace.strip('/') else ''


def _retarget(name: str, old_ns: str, new_ns: Optional[str]) -> str:
    """Move a recorded topic or node name from the recorded namespace to `new_ns`."""
    if new_ns is None:
        return name
    if old_ns and not name.startswith(old_ns + '/'):
        return name
    return _normalise_ns(new_ns) + name[len(old_ns):]


def _key(values: Mapping[str, str]) -> Tuple[Optional[str], int]:
    return values.get('input_source'), _count(values, 'input_stamp_ns')


def _count(values: Mapping[str, str], key: str) -> int:
    try:
        return int(values.get(key, -1))
    except ValueError:
        return -1


def _answers_everything(values: Mapping[str, str], after_last: bool, expected: int,
                        ours) -> bool:
    """Whether a ``plan_info`` answers every input the node has had, ours all among them.

    The node numbers parameter sets and messages alike and names only the newest input a
    plan took, so a plan that coalesced the recording's last input into a later one, or
    took inputs that arrived out of order, still answers everything when its
    ``input_seq`` is the node's ``inputs_received`` and that count includes all of ours.
    """
    seq = _count(values, 'input_seq')
    return (after_last and seq >= expected and seq == _count(values, 'inputs_received')
            and (_key(values) in ours or values.get('input_source') == PARAMETERS))


def _wait(condition: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def play_live(bag: Bag, *, rate: float = 1.0, namespace: Optional[str] = None,
              set_parameters: bool = True, overrides: Optional[Mapping[str, object]] = None,
              connect_timeout: float = 30.0, wait: float = 30.0,
              progress: Optional[Callable[[int, int], None]] = None) -> LiveResult:
    """Publish a recording's inputs to a running planner node with their recorded timing.

    Joins the ROS graph (``ROS_DOMAIN_ID`` and friends from the environment) with a node
    of its own, waits until the planner subscribes to every input topic the recording
    has, sets the recorded parameters (all but ``record``) atomically through the
    planner's parameter services, then publishes each recorded input, and applies each
    recorded parameter change, at its recorded time divided by `rate` (inputs on different
    topics at least :data:`TOPIC_SWITCH_GAP_S` apart, so that they arrive in the recorded
    order). Messages go out
    as recorded, header stamps included, so the node's ``plan_info`` names them.
    Finally it waits for the node to answer the last input the recording shows answered,
    or for a plan that took every input the node has had, all of these counted (inputs
    reordered on the way, or the last one coalesced into a later one, still answered).

    Parameters
    ----------
    bag : Bag
        The recording.
    rate : float
        Playback speed factor (2 = twice as fast).
    namespace : str, optional
        Namespace of the live node, if not the recorded one.
    set_parameters : bool
        Set the recorded parameters and changes on the node (else publish topics only).
    overrides : Mapping[str, object], optional
        Node parameters (``method``, ``w``, ...) to set instead of the recorded values.
    connect_timeout : float
        Longest wait for the node's subscriptions and parameter services [s].
    wait : float
        Longest wait for the answer to the last input after publishing [s].
    progress : callable, optional
        ``progress(done, total)`` after each input.

    Returns
    -------
    LiveResult
        Counts, the ``plan_info`` answers received and whether the last input was answered
        (None when the recording shows no answer to wait for).

    Raises
    ------
    ThreatPlannerError
        If no planner node subscribes in time, its parameter services do not answer, or it
        refuses the recorded parameters.

    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.signals import SignalHandlerOptions

    if not (math.isfinite(rate) and rate > 0.0):
        raise InputError(f'rate: must be finite and > 0, got {rate!r}')
    if not bag.inputs:
        raise RecordingError(f'{bag.path}: no inputs recorded: nothing to publish')
    overrides = {k: as_declared(k, v) for k, v in (overrides or {}).items() if v is not None}
    ns = bag.namespace if namespace is None else _normalise_ns(namespace)
    node_name = _retarget(bag.node_name, bag.namespace, namespace)
    answered_keys = {(p.source, p.stamp_ns) for p in bag.plans}
    last_key = next(((_retarget(i.source, bag.namespace, namespace), i.stamp_ns)
                     for i in reversed(bag.inputs)
                     if i.source != PARAMETERS and (i.source, i.stamp_ns) in answered_keys),
                    None)

    context = Context()
    apply_discovery_profile()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = executor = thread = None
    try:
        node = rclpy.create_node(f'threat_planner_replay_{os.getpid()}', context=context,
                                 start_parameter_services=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        cond = threading.Condition()
        answers: List[Tuple[float, Dict[str, str]]] = []

        def on_info(msg) -> None:
            try:
                values = plan_info_values(msg)
            except InputError:
                return
            values['level'] = level_name(msg.status[0].level)
            with cond:
                answers.append((time.monotonic(), values))
                cond.notify_all()

        from diagnostic_msgs.msg import DiagnosticArray
        info_sub = node.create_subscription(DiagnosticArray, f'{ns}/plan_info', on_info,
                                            LATCHED)
        publishers = {}
        for inp in bag.inputs:
            if inp.source != PARAMETERS and inp.source not in publishers:
                qos = INPUT_TOPICS[inp.kind][1]
                publishers[inp.source] = node.create_publisher(
                    type(inp.msg), _retarget(inp.source, bag.namespace, namespace), qos)

        def spin() -> None:
            try:
                executor.spin()
            except Exception:  # noqa: B902 - shutting the context down ends spin() so
                pass
        thread = threading.Thread(target=spin, daemon=True, name='replay-spin')
        thread.start()

        for pub in publishers.values():
            if not _wait(lambda pub=pub: pub.get_subscription_count() > 0, connect_timeout):
                raise ThreatPlannerError(
                    f'no subscriber on {pub.topic_name} within {connect_timeout:g} s: is the '
                    'planner node running, with the same ROS_DOMAIN_ID and namespace?')
        client = None
        parameter_sets = 0
        # The node's latched plan_info, if it has one, gives its input count before ours;
        # it comes just after the match, so the count waits a moment for it.
        if _wait(lambda: info_sub.get_publisher_count() > 0, connect_timeout):
            time.sleep(LATCHED_GRACE_S)
        with cond:
            baseline = max((_count(a, 'inputs_received') for _, a in answers), default=0)
        if set_parameters:
            client = AsyncParameterClient(node, node_name)
            if not client.wait_for_services(timeout_sec=connect_timeout):
                raise ThreatPlannerError(
                    f'parameter services of {node_name} not available within '
                    f'{connect_timeout:g} s (--no-parameters publishes the topics only)')
            initial = [Parameter.from_parameter_msg(p) for p in bag.initial_parameter_msgs
                       if p.name != 'record' and p.name not in overrides]
            initial += [Parameter(k, value=v) for k, v in overrides.items()]
            if initial:
                _set_parameters(client, initial, node_name, connect_timeout)
                parameter_sets += 1

        started = time.monotonic()
        t0 = bag.inputs[0].log_time_ns
        changes = 0
        previous, previous_t = None, -math.inf
        for n, inp in enumerate(bag.inputs, 1):
            delay = started + 1e-9 * (inp.log_time_ns - t0) / rate - time.monotonic()
            if inp.source != previous:
                delay = max(delay, previous_t + TOPIC_SWITCH_GAP_S - time.monotonic())
            if delay > 0:
                time.sleep(delay)
            previous, previous_t = inp.source, time.monotonic()
            if inp.source != PARAMETERS:
                publishers[inp.source].publish(inp.msg)
            elif client is not None:
                params = [Parameter.from_parameter_msg(p) for p in inp.msg.changed_parameters
                          if p.name != 'record' and p.name not in overrides]
                if params:
                    _set_parameters(client, params, node_name, connect_timeout)
                    changes += 1
                    parameter_sets += 1
            if progress is not None:
                progress(n, len(bag.inputs))
        last_published = time.monotonic()
        ours = {(_retarget(i.source, bag.namespace, namespace), i.stamp_ns)
                for i in bag.inputs if i.source != PARAMETERS}
        published = sum(i.source != PARAMETERS for i in bag.inputs)
        expected = baseline + parameter_sets + published
        last_answered = None
        if last_key is not None:
            def answered() -> bool:
                with cond:
                    return any(_key(a) == last_key or _answers_everything(
                        a, t >= last_published, expected, ours) for t, a in answers)
            last_answered = _wait(answered, wait)
        duration = time.monotonic() - started
        with cond:
            got = [a for t, a in answers
                   if _key(a) in ours
                   or (a.get('input_source') == PARAMETERS and t >= started)]
        return LiveResult(published, client is not None, changes, duration, got,
                          last_answered, ns, node_name)
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        if thread is not None:
            thread.join(5.0)


def _set_parameters(client, params, node_name: str, timeout: float) -> None:
    future = client.set_parameters_atomically(params)
    if not _wait(future.done, timeout):
        raise ThreatPlannerError(f'{node_name} did not answer a parameter change within '
                                 f'{timeout:g} s')
    result = future.result().result
    if not result.successful:
        names = ', '.join(p.name for p in params)
        raise ThreatPlannerError(f'{node_name} refused the recorded parameters ({names}): '
                                 f'{result.reason}')
