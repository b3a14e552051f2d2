"""Record an offline plan as the planner node would: ``threat-planner plan --record``.

:func:`record_plan` plans a scenario without ROS and records it as a planner node with
parameter ``record`` set would have: the full parameter set as a
``rcl_interfaces/msg/ParameterEvent`` on ``/parameter_events``, then the inputs
``start``, ``goal_pose``, the scenario's airspace (``no_fly_zones`` as a MarkerArray and
``terrain`` as a 32FC1 Image with its grid in the ``terrain_*`` parameters, each only when
the scenario has it) and ``threats`` (a float32 PointCloud2, which is what the plan
is computed from), then the outputs ``initial_path``, ``path``, ``network`` and
``plan_info``, with the node's topic names, types and QoS. Inputs become state and the
plan becomes messages through the node's own code (:mod:`threat_planner.ros.inputs`,
:mod:`threat_planner.ros.outputs`).
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
import time
from typing import Callable, Dict, Optional, Tuple

from geometry_msgs.msg import PoseStamped
import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import ParameterEvent

from threat_planner.bag.writer import McapRecorder
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import Scenario
from threat_planner.core.result import PlanResult
from threat_planner.errors import RecordingError
from threat_planner.ros.conversions import (image_from_terrain, ns_to_stamp,
                                            pointcloud2_from_threats, stamp_to_ns,
                                            zones_to_markers)
from threat_planner.ros.inputs import accept, InputState
from threat_planner.ros.interface import (INPUT_TOPICS, NODE_NAME, OUTPUT_TOPICS,
                                          PARAMETER_EVENT_TYPE, PARAMETER_EVENTS_QOS,
                                          PARAMETER_EVENTS_TOPIC)
from threat_planner.ros.outputs import (input_values, outcome_messages, PlanOutcome, PlanRequest,
                                        run_plan)
from threat_planner.ros.parameters import (as_declared, CONFIG_FIELDS, PARAMETER_DEFAULTS,
                                           settings_from_parameters)

__all__ = ['record_plan']


def _scenario_parameters(scenario: Scenario, config: PlannerConfig,
                         record: str) -> Dict[str, object]:
    defaults = PlannerConfig()
    for f in fields(PlannerConfig):
        if f.name not in CONFIG_FIELDS and getattr(config, f.name) != getattr(defaults, f.name):
            raise RecordingError(
                f'{f.name}={getattr(config, f.name)!r} is not a node parameter, so a '
                'recording cannot say how the plan was made')
    values = dict(PARAMETER_DEFAULTS)
    for name in CONFIG_FIELDS:
        values[name] = as_declared(name, getattr(config, name))
    box = scenario.box
    values['bounds'] = [float(v) for v in np.concatenate([box.lo, box.hi])]
    values['start'] = [float(v) for v in scenario.start]
    values['goal'] = [float(v) for v in scenario.goal]
    values['frame_id'] = scenario.frame_id
    values['record'] = record
    values['datum'] = [] if scenario.datum is None else scenario.datum.as_list()
    terrain = scenario.airspace.terrain
    if terrain is not None:   # airspace (issue 12): the grid of the terrain Image
        values['terrain_origin'] = [float(v) for v in terrain.origin]
        values['terrain_resolution'] = float(terrain.resolution)
        values['terrain_clearance'] = float(terrain.clearance)
        values['terrain_masking'] = bool(terrain.masking)
    return values


def _pose_msg(xyz: NDArray, frame_id: str, stamp_ns: int) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in xyz)
    msg.pose.orientation.w = 1.0
    return msg


def record_plan(scenario: Scenario, config: PlannerConfig, target, *,
                progress: Optional[Callable[[int, int], None]] = None
                ) -> Tuple[PlanResult, Path]:
    """Plan a scenario and record it as a planner node (namespace ``/``) would have.

    The recording holds what a node started with the scenario's bounds, start, goal and
    frame as parameters and ``config``'s settings would record when sent the scenario's
    start, goal and threats (in that order): the parameter event listing every
    parameter, the three inputs, then the four outputs of the one plan. The plan is made
    from the threats as the PointCloud2 carries them (float32), exactly as the node would,
    so it may differ from a plan of the float64 scenario in the last digits.

    Parameters
    ----------
    scenario : Scenario
        The planning problem.
    config : PlannerConfig
        Planner settings; only fields that are node parameters may differ from the
        defaults.
    target : str or os.PathLike
        A ``.mcap`` file, or a folder in which a rosbag2 bag directory is created.
    progress : callable, optional
        ``progress(done, total)`` for long sweeps, as :func:`threat_planner.core.planner.plan`.

    Returns
    -------
    result : PlanResult
        The plan.
    path : Path
        The ``.mcap`` file written.

    Raises
    ------
    RecordingError
        If the file cannot be written or ``config`` cannot be expressed as parameters.
    InputError, PlanningError
        As :func:`threat_planner.core.planner.plan`.

    """
    from rclpy.parameter import Parameter

    config.validated()
    values = _scenario_parameters(scenario, config, str(target))
    settings = settings_from_parameters(values)
    frame = settings.frame_id
    with McapRecorder(target, prefix=NODE_NAME) as rec:
        for name, (type_name, qos) in {**INPUT_TOPICS, **OUTPUT_TOPICS}.items():
            rec.add_topic(f'/{name}', type_name, qos)
        rec.add_topic(PARAMETER_EVENTS_TOPIC, PARAMETER_EVENT_TYPE, PARAMETER_EVENTS_QOS)
        t = time.time_ns()
        event = ParameterEvent(stamp=ns_to_stamp(t), node=f'/{NODE_NAME}')
        # Float arrays typed as declared: an empty one (datum) would read as bytes.
        event.new_parameters = [
            (Parameter(n, Parameter.Type.DOUBLE_ARRAY, [float(x) for x in v])
             if isinstance(v, list) else Parameter(n, value=v)).to_parameter_msg()
            for n, v in values.items()]
        rec.write(PARAMETER_EVENTS_TOPIC, event, log_time_ns=t)

        # The inputs, as threat_publisher sends them: start, goal, then the picture; each
        # taken into the node's state as the node takes it.
        state = InputState.from_parameters(values)
        for topic, xyz in (('start', scenario.start), ('goal_pose', scenario.goal)):
            msg = _pose_msg(xyz, frame, time.time_ns())
            rec.write(f'/{topic}', msg, log_time_ns=stamp_to_ns(msg.header.stamp))
            state = accept(state, topic, msg)
        air = scenario.airspace
        airspace_msgs = []   # airspace (issue 12): as a node would receive it
        if air.zones:
            airspace_msgs.append(('no_fly_zones', zones_to_markers(
                air.zones, frame, ns_to_stamp(time.time_ns()))))
        if air.terrain is not None:
            airspace_msgs.append(('terrain', image_from_terrain(
                air.terrain, frame, ns_to_stamp(time.time_ns()))))
        for topic, msg in airspace_msgs:
            rec.write(f'/{topic}', msg, log_time_ns=time.time_ns())
            state = accept(state, topic, msg)
        cloud_ns = time.time_ns()
        stamp = ns_to_stamp(cloud_ns)
        cloud = pointcloud2_from_threats(scenario.threats.positions,
                                         scenario.threats.intensities, frame, stamp)
        rec.write('/threats', cloud, log_time_ns=cloud_ns)
        state = accept(state, 'threats', cloud)

        # the node's number of the threats input, after start, goal_pose and the airspace
        seq = 3 + len(airspace_msgs)
        request = PlanRequest(seq=seq, source='/threats', stamp=stamp, received_ns=cloud_ns,
                              threats=state.threats, start=state.start, goal=state.goal,
                              settings=state.settings, airspace=state.airspace)

        def write(phase: str, outcome: PlanOutcome) -> None:
            plans = int(phase == 'done')
            values = input_values(seq, '/threats', stamp, frame, seq, 0, 0, plans)
            for topic, msg in outcome_messages(phase, outcome, values):
                rec.write(f'/{topic}', msg, log_time_ns=time.time_ns())

        outcome = run_plan(request, write, time.time_ns, progress=progress)
        if outcome.exception is not None:
            raise outcome.exception
        written = rec.path
    return outcome.result, written
