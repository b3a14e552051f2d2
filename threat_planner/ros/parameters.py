"""The node's parameters: declarations derived from the settings, and their validation.

Every parameter, its default, range, unit and help come from
:data:`threat_planner.core.inputs.settings.SETTINGS`; this module turns them into
``ParameterDescriptor`` s and checks a set of values as a whole
(:func:`settings_from_parameters`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Optional

import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
from rclpy.parameter import Parameter

from threat_planner.core.geo.frames import Datum
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.settings import NODE_SETTINGS
from threat_planner.core.world.threats import as_point, Box
from threat_planner.errors import InputError

__all__ = ['CONFIG_FIELDS', 'NodeSettings', 'PARAMETER_DEFAULTS', 'PLANNING_PARAMETERS',
           'as_declared', 'declare_all', 'descriptor', 'settings_from_parameters']


def _copy(value: object) -> object:
    return list(value) if isinstance(value, list) else value


#: Every parameter's default, as in ``config/planner.yaml`` (a fresh copy of each list).
PARAMETER_DEFAULTS: dict[str, object] = {
    name: _copy(s.default) for name, s in NODE_SETTINGS.items()}
#: Node parameters that are PlannerConfig fields.
CONFIG_FIELDS = tuple(name for name, s in NODE_SETTINGS.items() if s.scope == 'planner')
#: Parameters whose change can alter the plan; the rest (recording, input limits) cannot.
PLANNING_PARAMETERS = frozenset(PARAMETER_DEFAULTS) - {'record', 'max_threats',
                                                       'default_intensity',
                                                       'max_plan_time_s'}


@dataclass(frozen=True)
class NodeSettings:
    """The node's parameters, validated and converted.

    Attributes
    ----------
    config : PlannerConfig
        Planner settings.
    box : Box
        Flight box.
    frame_id : str
        Frame of all inputs and outputs.
    start : NDArray
        Start parameter (3,) [m].
    goal : NDArray
        Goal parameter (3,) [m].
    default_intensity : float
        Intensity of PoseArray threats.
    max_threats : int
        Largest accepted threat picture.
    max_plan_time_s : float
        Longest time of one plan [s].
    warm_replan : bool
        Whether the plan process replans warm from its previous plan when it may.
    record : str
        Recording target, '' for none.
    airspace_file : str
        Airspace YAML file, '' for none.
    terrain_origin : NDArray
        World (x, y) of pixel (0, 0) of a ``terrain`` height map (2,) [m].
    terrain_resolution, terrain_clearance : float
        Pixel spacing and smallest height above such a height map [m].
    terrain_masking : bool
        Whether such a height map masks the radars.
    datum : Datum or None
        WGS84 origin of frame_id, for NavSatFix inputs; None when parameter datum is [].

    """

    config: PlannerConfig
    box: Box
    frame_id: str
    start: NDArray
    goal: NDArray
    default_intensity: float
    max_threats: int
    max_plan_time_s: float
    record: str
    airspace_file: str = ''
    warm_replan: bool = True
    terrain_origin: NDArray = field(default_factory=lambda: np.zeros(2))
    terrain_resolution: float = 10.0
    terrain_clearance: float = 0.0
    terrain_masking: bool = False
    datum: Optional[Datum] = None


def _numbers(name: str, value: object, count: int, what: str) -> NDArray:
    if isinstance(value, (str, bytes, bool)) or not hasattr(value, '__len__'):
        raise InputError(f'{name}: expected {what}, got {value!r}')
    try:
        arr = np.asarray(list(value), dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{name}: expected {what}, got {value!r}') from None
    if arr.shape != (count,):
        raise InputError(f'{name}: expected {what}, got {arr.size} values')
    if not np.isfinite(arr).all():
        raise InputError(f'{name}: not finite: {arr.tolist()}')
    return arr


def settings_from_parameters(values: Mapping[str, object]) -> NodeSettings:
    """Validate parameter values and convert them to NodeSettings.

    Parameters
    ----------
    values : Mapping[str, object]
        Every name of :data:`PARAMETER_DEFAULTS` with its value (as rclpy gives it:
        float arrays may be lists, tuples or ``array.array``).

    Returns
    -------
    NodeSettings
        The converted settings.

    Raises
    ------
    InputError
        Naming the first bad parameter and its value; the text of
        ``PlannerConfig.validated()`` for planner settings.

    """
    try:
        config = PlannerConfig(**{name: values[name] for name in CONFIG_FIELDS})
    except TypeError as exc:
        raise InputError(f'planner settings: {exc}') from None
    config.validated()
    bounds = _numbers('bounds', values['bounds'], 6,
                      '6 numbers [xmin, ymin, zmin, xmax, ymax, zmax]')
    try:
        box = Box.from_corners(bounds[:3], bounds[3:])
    except InputError as exc:
        raise InputError(str(exc).replace('bounds.min', 'bounds').replace(
            'bounds.max', 'bounds')) from None
    start = as_point('start', _numbers('start', values['start'], 3, '[x, y, z]'))
    goal = as_point('goal', _numbers('goal', values['goal'], 3, '[x, y, z]'))
    for name in ('frame_id', 'default_intensity', 'max_threats', 'max_plan_time_s', 'record',
                 'airspace_file', 'terrain_resolution', 'terrain_clearance',
                 'terrain_masking', 'warm_replan'):
        NODE_SETTINGS[name].check(values[name])
    origin = _numbers('terrain_origin', values['terrain_origin'], 2, '[x, y]')
    raw = values.get('datum', [])
    datum = None if raw is None or (hasattr(raw, '__len__') and len(raw) == 0) else \
        Datum.parse(_numbers('datum', raw, 3, '[] or [lat, lon, h]'))
    return NodeSettings(config=config, box=box, frame_id=values['frame_id'], start=start,
                        goal=goal, default_intensity=float(values['default_intensity']),
                        max_threats=int(values['max_threats']),
                        max_plan_time_s=float(values['max_plan_time_s']),
                        record=values['record'].strip(),
                        airspace_file=values['airspace_file'].strip(),
                        terrain_origin=origin,
                        terrain_resolution=float(values['terrain_resolution']),
                        terrain_clearance=float(values['terrain_clearance']),
                        terrain_masking=bool(values['terrain_masking']),
                        warm_replan=bool(values['warm_replan']), datum=datum)


def declare_all(node) -> None:
    """Declare every parameter on `node` (an rclpy Node) with its default and descriptor."""
    for name, default in PARAMETER_DEFAULTS.items():
        if default != []:
            node.declare_parameter(name, default, descriptor(name))
            continue
        # geo (issue 26): rclpy types an empty default as a byte array, and a params
        # file's [] arrives unset: declared as a float array, then set empty.
        node.declare_parameter(name, Parameter.Type.DOUBLE_ARRAY, descriptor(name))
        if node.get_parameter_or(name).type_ == Parameter.Type.NOT_SET:
            node.set_parameters([Parameter(name, Parameter.Type.DOUBLE_ARRAY, [])])


def descriptor(name: str) -> ParameterDescriptor:
    """Return the ParameterDescriptor of parameter `name`: help, unit, rule and range."""
    s = NODE_SETTINGS[name]
    desc = ParameterDescriptor(name=name, description=s.doc, additional_constraints=s.rule)
    if s.lo is not None and s.hi is not None and s.kind is float:
        desc.floating_point_range = [FloatingPointRange(from_value=float(s.lo),
                                                        to_value=float(s.hi), step=0.0)]
    elif s.lo is not None and s.hi is not None and s.kind is int:
        desc.integer_range = [IntegerRange(from_value=int(s.lo), to_value=int(s.hi), step=1)]
    # One type per parameter, from the setting's kind: a value of another type (bounds as
    # strings, an integer array for a double array) is refused by rclpy with the reason,
    # at start-up as well as at run time.
    desc.type = _PARAMETER_TYPES[s.kind]
    desc.dynamic_typing = False
    return desc


_PARAMETER_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
                    float: ParameterType.PARAMETER_DOUBLE,
                    str: ParameterType.PARAMETER_STRING,
                    list: ParameterType.PARAMETER_DOUBLE_ARRAY}


def as_declared(name: str, value: object) -> object:
    """Give a value the type its parameter is declared with (a float k, an int n_points)."""
    kind = NODE_SETTINGS[name].kind
    return kind(value) if kind in (bool, int, float) else value
