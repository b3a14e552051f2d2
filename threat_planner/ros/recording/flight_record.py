"""Record a simulated flight as a bag: ``threat-planner fly --record flight.mcap``.

:func:`record_flight` flies a scenario with :func:`threat_planner.flight.fly.fly` and a
:class:`FlightRecorder` as its observer, which writes what a planner node, its
``threat_publisher`` and ``sim_vehicle`` would have put on their topics, with the node's
names, types and QoS:

* ``/flight_setup`` (std_msgs/String, at t = 0): JSON of everything needed to fly it
  again (``format`` :data:`FLIGHT_FORMAT`, the scenario in its YAML layout, every event,
  the planner settings, speed, commit, step, start heading, longest flight); a bag with
  this topic is a flight bag (:func:`is_flight_bag`);
* ``/parameter_events``: the node's parameter set for the flight, as ``plan --record``;
* ``/start``, ``/goal_pose`` (at t = 0 and at each goal event) and ``/no_fly_zones``
  (when there are zones);
* ``/threats`` (sensor_msgs/PointCloud2, x y z intensity vx vy vz as the node reads):
  the picture the planner knows, at t = 0, after each event that changes it and at 2 Hz
  while a threat moves, stamped when its positions hold;
* ``/events`` (std_msgs/String): each event as JSON (``{"t": 2.0, "add_threat": {...}}``,
  the events file's layout) at the step it was applied;
* ``/path`` (nav_msgs/Path): each trajectory flown, header stamped with its t0 and pose k
  with t0 + t_k, as the node publishes them;
* ``/plan_info`` (diagnostic_msgs/DiagnosticArray): one per plan, with the node's keys
  where they apply (``plan``, ``plan_reason``, ``J`` of the published path, ``replan_J``,
  ``rounds``, ``entry_*``, ``t0_ns``, ``eta_s``, ``plan_wall_ms`` the latency);
* ``/odom`` (nav_msgs/Odometry): the vehicle at t = 0 and after every step (20 Hz);
* ``/flight_result`` (std_msgs/String, at the end): J_flown, reached_goal and the rest.

The node's ``record`` parameter holds the file's name, not its folder. Log times and
stamps are flight time after the fixed :data:`EPOCH_NS`, and the file is
written without the recorder's wall-clock flush timer, so recording one flight twice
gives the same bytes except for the latencies (``plan_wall_ms``); with
``latency=False`` (``--record-no-latency``) those are left out and the files are equal.
"""

from __future__ import annotations

from dataclasses import asdict
import json
from pathlib import Path
from typing import Optional

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import ParameterEvent
from std_msgs.msg import String

from threat_planner.bag.reader import recorded_topics
from threat_planner.bag.writer import McapRecorder
from threat_planner.core.flight.timed_cost import timed_path_cost
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.trajectory import quaternions, yaw_pitch
from threat_planner.core.world.airspace import zone_to_mapping
from threat_planner.flight.events import apply_event, Event
from threat_planner.flight.fly import finite_json, fly, FlightReport, scenario_timeline
from threat_planner.ros.conversions import (ns_to_stamp, path_to_msg, plan_info_msg,
                                            pointcloud2_from_threats, zones_to_markers)
from threat_planner.ros.interface import (INPUT_TOPICS, LATCHED, NODE_NAME, OUTPUT_TOPICS,
                                          PARAMETER_EVENT_TYPE, PARAMETER_EVENTS_QOS,
                                          PARAMETER_EVENTS_TOPIC)
from threat_planner.ros.recording.record import _scenario_parameters

__all__ = ['EPOCH_NS', 'FLIGHT_FORMAT', 'FlightRecorder', 'RESULT_TOPIC', 'SETUP_TOPIC',
           'event_mapping', 'is_flight_bag', 'record_flight']

#: ``format`` of ``/flight_setup``: what replay understands.
FLIGHT_FORMAT = 'threat_planner flight 1'
#: Take-off, t = 0, on the bag's clock: 2026-01-01T00:00:00Z [ns].
EPOCH_NS = 1_767_225_600 * 10 ** 9
SETUP_TOPIC = '/flight_setup'
RESULT_TOPIC = '/flight_result'
EVENTS_TOPIC = '/events'
STRING_TYPE = 'std_msgs/msg/String'
#: Moving threats are published this often, as threat_publisher does [s].
CLOUD_PERIOD_S = 0.5
#: The body frame of the odometry's twist (REP-105), as sim_vehicle's.
CHILD_FRAME = 'base_link'
_TOPICS = ('start', 'goal_pose', 'no_fly_zones', 'threats', 'odom')


def event_mapping(event: Event) -> dict:
    """Return `event` in the events file's layout: ``{'t': 2.0, 'add_threat': {...}}``."""
    v = event.values
    if event.kind == 'goal':
        body: object = [float(x) for x in v['goal']]
    elif event.kind == 'add_zone':
        body = zone_to_mapping(v['zone'])
    else:
        body = dict(v)
    return {'t': float(event.t), event.kind: finite_json(body)}


def is_flight_bag(path, *, tolerant: bool = False) -> bool:
    """Whether the recording at `path` is a flight (it has ``/flight_setup``)."""
    return recorded_topics(path, tolerant=tolerant).get(SETUP_TOPIC) == STRING_TYPE


def _ns(t: float) -> int:
    return EPOCH_NS + int(round(float(t) * 1e9))


def _json(data: object) -> String:
    return String(data=json.dumps(finite_json(data), allow_nan=False, separators=(',', ':')))


def _pose(xyz: NDArray, frame_id: str, stamp_ns: int) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in xyz)
    msg.pose.orientation.w = 1.0
    return msg


class FlightRecorder:
    """The observer of :func:`~threat_planner.flight.fly.fly` that writes the bag.

    Parameters
    ----------
    target : str or os.PathLike
        A ``.mcap`` file, or a folder for a rosbag2 bag directory.
    scenario : Scenario
        The scenario flown.
    events : list of Event
        Its events.
    config : PlannerConfig
        The planner settings (fields that are not node parameters must be the defaults).
    setup : dict
        The other arguments of ``fly`` (``speed``, ``commit_s``, ``dt``, ``heading``,
        ``max_time_s``, ``hindsight``), for ``/flight_setup``.
    latency : bool
        Write each plan's wall-clock latency (``plan_wall_ms``); False gives a file that
        is the same bytes each time the flight is recorded.

    Raises
    ------
    RecordingError
        If the file cannot be created or `config` cannot be node parameters.

    """

    def __init__(self, target, scenario, events: list[Event], config: PlannerConfig,
                 setup: dict, *, latency: bool = True) -> None:
        from rclpy.parameter import Parameter
        # the file name, not its folder: the same flight recorded anywhere is the same bytes
        values = _scenario_parameters(scenario, config, Path(target).name)
        values['speed_mps'] = float(setup['speed'])
        values['commit_s'] = float(setup['commit_s'])
        self._frame = scenario.frame_id
        self._cfg, self._latency = config, latency
        self._timeline = scenario_timeline(scenario)
        self._zones = [z for z in scenario.airspace.zones
                       if not z.label.startswith('threats[')]
        self._heading = setup.get('heading')
        self._speed = float(setup['speed'])
        self._plans = 0
        self._changed = False
        self._next_cloud = CLOUD_PERIOD_S
        self._rec = McapRecorder(target, prefix=f'{NODE_NAME}_flight', flush_interval_s=None)
        rec = self._rec
        try:
            for name in _TOPICS:
                rec.add_topic(f'/{name}', *INPUT_TOPICS[name])
            for name in ('path', 'plan_info'):
                rec.add_topic(f'/{name}', *OUTPUT_TOPICS[name])
            for topic in (SETUP_TOPIC, EVENTS_TOPIC, RESULT_TOPIC):
                rec.add_topic(topic, STRING_TYPE, LATCHED)
            rec.add_topic(PARAMETER_EVENTS_TOPIC, PARAMETER_EVENT_TYPE, PARAMETER_EVENTS_QOS)
            doc = {'format': FLIGHT_FORMAT, 'epoch_ns': EPOCH_NS,
                   'scenario': scenario.to_dict(),
                   'events': [event_mapping(e) for e in events],
                   'config': asdict(config), **setup}
            rec.write(SETUP_TOPIC, _json(doc), log_time_ns=EPOCH_NS)
            event = ParameterEvent(stamp=ns_to_stamp(EPOCH_NS), node=f'/{NODE_NAME}')
            event.new_parameters = [
                (Parameter(n, Parameter.Type.DOUBLE_ARRAY, [float(x) for x in v])
                 if isinstance(v, list) else Parameter(n, value=v)).to_parameter_msg()
                for n, v in values.items()]
            rec.write(PARAMETER_EVENTS_TOPIC, event, log_time_ns=EPOCH_NS)
            rec.write('/start', _pose(scenario.start, self._frame, EPOCH_NS),
                      log_time_ns=EPOCH_NS)
            self._goal(0.0, scenario.goal)
            if self._zones:
                self._write_zones(0.0)
            self._cloud(0.0)
        except BaseException:
            rec.close()
            raise

    # -- fly()'s observer ----------------------------------------------------------------
    def on_start(self, position: NDArray, heading: NDArray) -> None:
        """Write the vehicle at t = 0."""
        self._odom(0.0, position, heading)

    def on_event(self, t: float, event: Event) -> None:
        """Write `event` at `t` and apply it to the picture published."""
        self._rec.write(EVENTS_TOPIC, _json(event_mapping(event)), log_time_ns=_ns(t))
        goal = apply_event(event, self._timeline, self._zones)
        if goal is not None:
            self._goal(t, goal)
        elif event.kind == 'add_zone':
            self._write_zones(t)
        else:
            self._changed = True

    def on_replan(self, record: dict, points: Optional[NDArray],
                  times: Optional[NDArray]) -> None:
        """Write the picture if an event changed it, the trajectory and its plan_info."""
        t = float(record['t'])
        if self._changed:
            self._cloud(t)
        self._plans += 1
        n = self._plans
        source = '/start' if n == 1 else EVENTS_TOPIC
        stamp = ns_to_stamp(_ns(t))
        values: dict = {'input_seq': n, 'input_source': source, 'input_stamp_ns': _ns(t),
                        'frame_id': self._frame, 'flight_t_s': t,
                        'plan_reason': record.get('reason', '')}
        if points is None:
            if record.get('ok', True):
                values['note'] = record.get('note', '')
                msg = plan_info_msg('OK', f"plan for input #{n} ({source}): "
                                    f"{values['note']}", values, stamp)
            else:
                values['error'] = record.get('error', '')
                msg = plan_info_msg('ERROR', f"plan for input #{n} ({source}) failed: "
                                    f"{values['error']}", values, stamp)
            self._rec.write('/plan_info', msg, log_time_ns=_ns(t))
            return
        cost = timed_path_cost(points, times, self._timeline, self._cfg.w)
        first = 'timed' if self._heading is None else 'from_vehicle'
        kind = 'in_flight' if n > 1 else first
        values.update({
            'plan': kind, 'method': self._cfg.method, 'w': self._cfg.w,
            'threats': len(self._timeline.active(t)),
            'J': cost.J, 'J_L': cost.J_L, 'J_R': cost.J_R,
            'replan_J': record.get('J_planned'), 'rounds': record.get('rounds'),
            'start': 'warm' if record.get('warm') else 'cold',
            'path_points': len(points), 't0_ns': _ns(t),
            'speed_mps': self._speed, 'eta_s': float(times[-1]) - t,
            'commit_s': self._cfg.commit_s})
        if n == 1 and self._heading is not None:
            values['start_heading'] = '[' + ', '.join(f'{v:.9g}' for v in self._heading) + ']'
        for key in ('entry_turn_deg', 'entry_feasible'):
            if key in record:
                values[key] = record[key]
        if self._latency:
            values['plan_wall_ms'] = record.get('latency_ms')
        self._rec.write('/path', path_to_msg(points, self._frame, stamp,
                                             np.maximum(np.asarray(times) - t, 0.0)),
                        log_time_ns=_ns(t))
        level = 'WARN' if record.get('entry_feasible') is False else 'OK'
        msg = plan_info_msg(level, f'plan for input #{n} ({source}): J={cost.J:.6g} at '
                            f't={t:g} s ({values["plan_reason"]})', values, stamp)
        self._rec.write('/plan_info', msg, log_time_ns=_ns(t))

    def on_step(self, t: float, position: NDArray, heading: NDArray) -> None:
        """Write the vehicle's odometry, and the moving picture every CLOUD_PERIOD_S."""
        if t + 1e-9 >= self._next_cloud:
            if self._moving(t):
                self._cloud(t)
            self._next_cloud += CLOUD_PERIOD_S
        self._odom(t, position, heading)

    # -- the file ------------------------------------------------------------------------
    def finish(self, report: FlightReport) -> Path:
        """Write ``/flight_result`` at the flight's end, close the file; return its path."""
        data = {k: v for k, v in report.as_dict().items() if k != 'flown'}
        data.update(t_end_s=float(report.times[-1]), plans=len(report.replans))
        if not self._latency:
            data['replans'] = [{k: v for k, v in r.items() if k != 'latency_ms'}
                               for r in data['replans']]
        self._rec.write(RESULT_TOPIC, _json(data), log_time_ns=_ns(report.times[-1]))
        return self.close()

    def close(self) -> Path:
        """Close the file (idempotent); return its path."""
        self._rec.close()
        return self._rec.path

    # -- messages ------------------------------------------------------------------------
    def _moving(self, t: float) -> bool:
        _, _, _, vel, _, _, _ = self._timeline.pieces()
        k = self._timeline.active(t)
        return bool(len(k) and np.any(vel[k] != 0.0))

    def _cloud(self, t: float) -> None:
        snap = self._timeline.snapshot(t)
        k = np.argsort(snap.ids, kind='stable')
        msg = pointcloud2_from_threats(snap.field.positions[k], snap.field.intensities[k],
                                       self._frame, ns_to_stamp(_ns(t)), snap.velocities[k])
        self._rec.write('/threats', msg, log_time_ns=_ns(t))
        self._changed = False

    def _goal(self, t: float, goal: NDArray) -> None:
        self._rec.write('/goal_pose', _pose(goal, self._frame, _ns(t)), log_time_ns=_ns(t))

    def _write_zones(self, t: float) -> None:
        msg = zones_to_markers(self._zones, self._frame, ns_to_stamp(_ns(t)))
        self._rec.write('/no_fly_zones', msg, log_time_ns=_ns(t))

    def _odom(self, t: float, position: NDArray, heading: NDArray) -> None:
        msg = Odometry()
        msg.header.stamp = ns_to_stamp(_ns(t))
        msg.header.frame_id = self._frame
        msg.child_frame_id = CHILD_FRAME
        p = msg.pose.pose.position
        p.x, p.y, p.z = (float(c) for c in position)
        q = quaternions(yaw_pitch(np.asarray(heading, float)[None]))[0]
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = (float(c) for c in q)
        msg.twist.twist.linear.x = self._speed
        self._rec.write('/odom', msg, log_time_ns=_ns(t))


def record_flight(scenario, events: list[Event], config: PlannerConfig, speed: float,
                  target, *, latency: bool = True, **fly_options) -> tuple[FlightReport, Path]:
    """Fly `scenario` through `events` (:func:`~threat_planner.flight.fly.fly`) and record it.

    Parameters
    ----------
    scenario, events, config, speed
        As :func:`~threat_planner.flight.fly.fly`.
    target : str or os.PathLike
        A ``.mcap`` file, or a folder for a rosbag2 bag directory.
    latency : bool
        Record each plan's wall-clock latency (False: the same bytes every time).
    **fly_options
        ``commit_s``, ``dt``, ``heading``, ``max_time_s``, ``hindsight`` of ``fly``.

    Returns
    -------
    report : FlightReport
        The flight.
    path : Path
        The ``.mcap`` file written.

    Raises
    ------
    RecordingError
        If the file cannot be written or `config` cannot be node parameters.
    InputError, PlanningError
        As :func:`~threat_planner.flight.fly.fly`.

    """
    from threat_planner.flight.fly import DT
    heading = fly_options.get('heading')
    setup = {'speed': float(speed), 'commit_s': float(fly_options.get('commit_s', 2.0)),
             'dt': float(fly_options.get('dt', DT)),
             'heading': None if heading is None else [float(v) for v in heading],
             'max_time_s': fly_options.get('max_time_s'),
             'hindsight': bool(fly_options.get('hindsight', True))}
    recorder = FlightRecorder(target, scenario, events, config, setup, latency=latency)
    try:
        report = fly(scenario, events, config, speed, observer=recorder, **fly_options)
    except BaseException:
        recorder.close()
        raise
    return report, recorder.finish(report)
