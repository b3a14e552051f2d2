"""Every setting of the planner and the node, declared once.

Each :class:`Setting` names its type, default, range, unit and one-line help. From this
table come :class:`~threat_planner.core.inputs.config.PlannerConfig`'s defaults and validation,
the node's parameters with their ``ParameterDescriptor`` ranges
(:mod:`threat_planner.ros.parameters`), the comments of ``config/planner.yaml``
(:func:`params_file_text`, checked by a test) and the command line's planner options with
their defaults in ``--help`` (:mod:`threat_planner.cli.options`).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import textwrap
from typing import Callable, Optional

from threat_planner.core.inputs.rcs import parse_rcs
from threat_planner.errors import InputError

__all__ = ['CANDIDATE_RULES', 'COST_MODELS', 'METHODS', 'NETWORKS', 'NODE_SETTINGS', 'NO_LIMITS',
           'PHYSICAL_LIMITS', 'PLANNER_SETTINGS', 'SETTINGS', 'Setting', 'params_file_text']

METHODS = ('paper', 'improved', 'best')
NETWORKS = ('box', 'threats')
CANDIDATE_RULES = ('spread', 'nearest')
COST_MODELS = ('paper', 'detection')


@dataclass(frozen=True)
class Setting:
    """One setting: what it is, its default and the values it takes.

    Attributes
    ----------
    name : str
        Field of PlannerConfig (scope 'planner') or node parameter name.
    kind : type
        bool, int, float, str, or list for a fixed-length float array.
    default : object
        Default value.
    help : str
        One line of help, without the unit.
    unit : str
        Unit, for example ``'m'`` or ``'deg'``; '' for none.
    lo, hi : float, optional
        Range of a number; None for unbounded.
    lo_open, hi_open : bool
        Whether the range excludes its ends.
    choices : tuple of str, optional
        The values a string takes.
    length : int
        Number of values of a float array.
    scope : str
        ``'planner'`` (a PlannerConfig field) or ``'node'`` (the node's own).
    node : bool
        Whether the node declares it as a parameter.
    cli : str, optional
        Command-line option (without ``--``), or None for none.
    non_empty : bool
        A string that must not be blank.
    empty_ok : bool
        A float array that may also be empty (``[]`` = none).
    parse : callable, optional
        ``parse(value, name)`` raising InputError for a string the kind alone allows but
        the setting does not (``rcs``).
    rule_text : str, optional
        The constraint in words where the kind and range say it badly (``swerling``: 'must
        be 0 or 1', not 'an integer >= 0 and <= 1'); None to derive it.

    """

    name: str
    kind: type
    default: object
    help: str
    unit: str = ''
    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    hi_open: bool = False
    choices: Optional[tuple[str, ...]] = None
    length: int = 0
    scope: str = 'planner'
    node: bool = True
    cli: Optional[str] = None
    non_empty: bool = False
    empty_ok: bool = False
    parse: Optional[Callable[[object, str], object]] = None
    rule_text: Optional[str] = None

    @property
    def rule(self) -> str:
        """The constraint in words, as error messages and descriptors give it."""
        if self.rule_text is not None:
            return self.rule_text
        if self.choices is not None:
            return f'must be one of {", ".join(self.choices)}'
        if self.kind is str:
            return 'must be a non-empty string' if self.non_empty else 'must be a string'
        if self.kind is bool:
            return 'must be true or false'
        if self.kind is list:
            return f'{self.length} finite numbers' + (' or none' if self.empty_ok else '')
        lo = '<' if self.lo_open else '<='
        hi = '<' if self.hi_open else '<='
        if self.lo_open and self.hi_open and self.lo is not None and self.hi is not None:
            return f'must satisfy {self.lo:g} {lo} {self.name} {hi} {self.hi:g}'
        num = (lambda v: str(int(v))) if self.kind is int else (lambda v: f'{v:g}')
        parts = []
        if self.lo is not None:
            parts.append(f'{">" if self.lo_open else ">="} {num(self.lo)}')
        if self.hi is not None:
            parts.append(f'{"<" if self.hi_open else "<="} {num(self.hi)}')
        if self.kind is int:
            return ' and '.join(['must be an integer' + (f' {parts[0]}' if parts else '')]
                                + parts[1:])
        return ' and '.join(['must be finite'] + parts)

    @property
    def span(self) -> str:
        """The range in short form (``0 < w < 1``, ``2..10000``), '' if unbounded."""
        if self.kind not in (int, float) or (self.lo is None and self.hi is None):
            return ''
        if self.kind is int and self.lo is not None and self.hi is not None:
            return f'{int(self.lo)}..{int(self.hi)}'
        lo = '' if self.lo is None else f'{self.lo:g} {"<" if self.lo_open else "<="} '
        hi = '' if self.hi is None else f' {"<" if self.hi_open else "<="} {self.hi:g}'
        return f'{lo}{self.name}{hi}'

    @property
    def doc(self) -> str:
        """Help with the unit, as one line."""
        return self.help + (f' [{self.unit}]' if self.unit else '')

    def check(self, value: object) -> None:
        """Raise InputError naming this setting unless `value` is allowed.

        Float arrays are checked by the code that interprets them (bounds, start, goal).
        """
        if self.kind is list:
            return
        if not self._allowed(value):
            raise InputError(f'{self.name}: {self.rule}, got {_plain(value)}')
        if self.parse is not None:
            self.parse(value, self.name)

    def _allowed(self, value: object) -> bool:
        if self.choices is not None:
            return value in self.choices
        if self.kind is str:
            return isinstance(value, str) and (not self.non_empty or bool(value.strip()))
        if self.kind is bool:
            return isinstance(value, bool)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        # Finite first: int() of NaN or infinity raises instead of answering.
        if not math.isfinite(value):
            return False
        if self.kind is int and value != int(value):
            return False
        if self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo):
            return False
        if self.hi is not None and (value >= self.hi if self.hi_open else value > self.hi):
            return False
        return True


def _plain(value: object) -> str:
    """Show a value as the user typed it: plain numbers, not numpy reprs."""
    if hasattr(value, 'item') and not isinstance(value, (str, bytes)):
        try:
            value = value.item()
        except (ValueError, TypeError):
            pass
    return repr(value)


#: Every setting, planner settings first, in the order of ``config/planner.yaml``.
SETTINGS: tuple[Setting, ...] = (
    Setting('w', float, 0.5, 'Threat weight in J = w J_R + (1 - w) J_L', lo=0.0, hi=1.0,
            lo_open=True, hi_open=True, cli='w'),
    Setting('method', str, 'best', "Planning method: 'paper', 'improved' or 'best'",
            choices=METHODS, cli='method'),
    Setting('k', float, 1000.0, 'Spring coefficient of the smoothing chain', lo=0.0,
            hi=1.0e6, lo_open=True, cli='k'),
    Setting('auto_k', bool, False, 'Sweep k over 500..3000 for the least J (paper Case 3)',
            cli='auto-k'),
    Setting('damping', float, 20.0, 'Damping coefficient b between neighbouring chain masses',
            lo=0.0, hi=1.0e6),
    Setting('mass', float, 1.0, 'Mass M of each chain point', lo=0.0, hi=1.0e6,
            lo_open=True),
    Setting('q', float, 500.0, 'Repulsion constant Q of the threat potential', lo=0.0,
            hi=1.0e9),
    Setting('n_points', int, 40, 'Number of chain segments n of the final path (n + 1 points)',
            lo=2, hi=10_000, cli='n-points'),
    Setting('max_pitch_deg', float, 45.0, 'Pitch limit', unit='deg', lo=0.0, hi=90.0,
            lo_open=True, cli='max-pitch'),
    Setting('max_turn_deg', float, 60.0, 'Turn limit between consecutive segments',
            unit='deg', lo=0.0, hi=180.0, lo_open=True, cli='max-turn'),
    # Physical limits of method 'best' (the paper's per-vertex angles above stay the check
    # of 'paper' and 'improved'), ON by default, chosen for a small UAV at ~10 m/s: climb
    # and dive 30 deg (a multirotor climbs and descends steeper; a small fixed-wing's
    # excess thrust and airspeed envelope allow ~30 deg, and a 30 deg glide is a common
    # autopilot default), turn radius v^2 / (g tan(bank)) = 10 m at 10 m/s and 45 deg bank
    # (a multirotor at speed is comfortable at that radius too). The limited yardstick of
    # bench/toolkit/yardstick.py uses the same 30 / 30 / 10 m (PHYSICAL_LIMITS), so the bench
    # compares like with like. 90 / 90 / 0 switch them off.
    Setting('max_climb_deg', float, 30.0,
            "Steepest climb of any segment, atan2(dz, horizontal) ('best'; 90 = off)",
            unit='deg', lo=0.0, hi=90.0, lo_open=True, cli='max-climb'),
    Setting('max_dive_deg', float, 30.0,
            "Steepest dive of any segment, atan2(-dz, horizontal) ('best'; 90 = off)",
            unit='deg', lo=0.0, hi=90.0, lo_open=True, cli='max-dive'),
    Setting('min_turn_radius_m', float, 10.0,
            "Smallest fillet at a corner: arc tangent to both segments within half of each "
            "('best'; 0 = off)",
            unit='m', lo=0.0, hi=1.0e6, cli='min-turn-radius'),
    Setting('min_altitude_m', float, 0.0,
            "Lowest height of the path above the box floor, start and goal exempt ('best'; "
            "0 = off)", unit='m', lo=0.0, hi=1.0e6, cli='min-altitude'),
    # Trajectories (issue 44): the speed times the path (Path stamps, --json t and eta_s,
    # the exports' DO_CHANGE_SPEED); no stage of the planner reads it, so it changes no plan.
    Setting('speed_mps', float, 20.0,
            'Cruise speed the path is flown at, which times it (pose stamps, t and eta_s, '
            'the exports\' DO_CHANGE_SPEED); the path itself does not depend on it',
            unit='m/s', lo=0.0, hi=1000.0, lo_open=True, cli='speed'),
    # Flight (issue 44): a replan in flight keeps this much of the trajectory being flown.
    Setting('commit_s', float, 2.0,
            'Time of the trajectory ahead of the vehicle a replan in flight keeps unchanged, '
            'so the path never jumps under its follower (0 = replan from where it is)',
            unit='s', lo=0.0, hi=60.0, cli='commit'),
    # Detection (issue 43): the cost minimised, and the radar model every plan's
    # P_detect is reported under (core/detection/model.py states it).
    Setting('cost_model', str, 'paper',
            "Cost minimised: 'paper' (J = w J_R + (1 - w) J_L) or 'detection' "
            "(w H + (1 - w) L / L_0, H the cumulative detection hazard; method best)",
            choices=COST_MODELS, cli='cost'),
    Setting('max_detection', float, 1.0,
            "With cost_model detection, the shortest path whose P_detect is at most this "
            "(1 = no bound: minimise w H + (1 - w) L / L_0 instead)",
            lo=0.0, hi=1.0, lo_open=True, cli='max-detection'),
    Setting('scan_period_s', float, 1.0, 'Radar scan period T of the detection model',
            unit='s', lo=0.0, hi=3600.0, lo_open=True, cli='scan-period'),
    Setting('p_fa', float, 1.0e-6, 'False-alarm probability per scan of the detection model',
            lo=0.0, hi=1.0, lo_open=True, hi_open=True, cli='p-fa'),
    Setting('swerling', int, 1,
            'Swerling case of the detection model: 0 (steady target) or 1 (fluctuating)',
            lo=0, hi=1, cli='swerling', rule_text='must be 0 or 1'),
    Setting('rcs', str, 'constant 1.0',
            "Radar cross-section of the UAV: 'constant S' [m^2] or 'ellipsoid A B C' "
            "(semi-axes [m] along the nose, the right wing and down)", cli='rcs',
            parse=parse_rcs, rule_text="must be 'constant S' or 'ellipsoid A B C'"),
    Setting('entry_candidates', int, 3, 'Network nodes tried as entry and as exit',
            lo=1, hi=64, cli='entry-candidates'),
    Setting('candidates', str, 'spread',
            "How 'improved' picks entry/exit nodes: 'spread' (nearest node of each of K "
            "sectors around the start-goal axis, margin slivers left out, as the paper's "
            "Fig. 11) or 'nearest' (the K nearest nodes)", choices=CANDIDATE_RULES,
            node=False, cli='candidates'),
    Setting('network', str, 'box',
            "Network: 'box' (threats plus the flight box's surface: covers the box, takes "
            "flat or tiny inputs) or 'threats' (the paper's: threats only, their hull)",
            choices=NETWORKS, node=False, cli='network'),
    Setting('routes', int, 6, "Distinct network routes screened by 'best' (plus the line)",
            lo=1, hi=32, node=False),
    Setting('surface_seeds', bool, True,
            "Also screen least-J routes over box lattices: its surface, and without flight "
            "limits its volume ('best' only)",
            node=False),
    Setting('box_divisions', int, 2, 'Intervals per box edge of the auxiliary surface lattice',
            lo=1, hi=16, node=False),
    Setting('optimise', bool, True, "Run the direct J minimisation ('best' only)",
            node=False),
    Setting('confine_to_box', bool, True, 'Keep the optimised path inside the bounds',
            cli='leave-box'),
    Setting('max_smoothing_steps', int, 4000, 'Step limit of the chain integration', lo=0,
            hi=10_000_000, node=False),
    Setting('bounds', list, [0.0, 0.0, 0.0, 100.0, 100.0, 100.0],
            'Flight box [xmin, ymin, zmin, xmax, ymax, zmax] in frame_id', unit='m',
            length=6, scope='node'),
    Setting('frame_id', str, 'map',
            'Frame of every input and output; inputs in another frame are refused',
            scope='node', non_empty=True),
    # geo (issue 26): what ties frame_id to WGS84, for the NavSatFix inputs.
    Setting('datum', list, [],
            'WGS84 origin [lat, lon, h] of frame_id (East-North-Up, h above the ellipsoid), '
            "for NavSatFix inputs on start_fix and goal_fix; [] = none", unit='deg, deg, m',
            length=3, scope='node', empty_ok=True),
    Setting('start', list, [0.0, 0.0, 50.0],
            'Start [x, y, z], used until a start message arrives; setting it replaces the '
            'current start', unit='m', length=3, scope='node'),
    Setting('goal', list, [100.0, 100.0, 50.0],
            'Goal [x, y, z], used until a goal_pose message arrives; setting it replaces '
            'the current goal', unit='m', length=3, scope='node'),
    Setting('default_intensity', float, 100000.0,
            'Intensity F given to every threat of a PoseArray', lo=0.0, hi=1.0e12,
            lo_open=True, scope='node'),
    Setting('max_threats', int, 10000, 'Largest threat picture accepted', lo=0,
            hi=1_000_000, scope='node'),
    Setting('warm_replan', bool, True,
            'Replan from the previous path after a small change (threats moved by at most 1 % '
            'of the box, start along the last path; core/methods/warm.py); plan_info says warm '
            'or cold',
            scope='node'),
    Setting('max_plan_time_s', float, 60.0,
            'Longest time one plan may take; a longer one is stopped and reported as timed '
            'out in plan_info', unit='s', lo=0.0, hi=86400.0, lo_open=True, scope='node'),
    # airspace (issue 12): the file's keys are the scenario's (no_fly_zones, terrain); the
    # terrain_* settings describe the grid of a height map received on topic 'terrain'.
    Setting('airspace_file', str, '',
            "YAML file with no_fly_zones and terrain (the scenario keys), loaded at start-up "
            "and on change; '' = none", scope='node'),
    Setting('terrain_origin', list, [0.0, 0.0],
            "World [x, y] of pixel (0, 0) of a height map on topic 'terrain'", unit='m',
            length=2, scope='node'),
    Setting('terrain_resolution', float, 10.0,
            "Spacing of the pixels of a height map on topic 'terrain'", unit='m', lo=0.0,
            hi=1.0e6, lo_open=True, scope='node'),
    Setting('terrain_clearance', float, 0.0,
            "Smallest height above a height map on topic 'terrain'", unit='m', lo=0.0,
            hi=1.0e6, scope='node'),
    Setting('terrain_masking', bool, False,
            "Whether a height map on topic 'terrain' hides the UAV from radars",
            scope='node'),
    Setting('record', str, '',
            "MCAP recording of inputs and outputs: a path ending in .mcap (one file) or a "
            "folder (one bag per run); '' = off", scope='node'),
)

#: The physical limits in force by default (see the settings above), also the limited
#: yardstick's (bench/toolkit/yardstick.py).
PHYSICAL_LIMITS = {'max_climb_deg': 30.0, 'max_dive_deg': 30.0, 'min_turn_radius_m': 10.0}
#: The settings that switch the physical limits off.
NO_LIMITS = {'max_climb_deg': 90.0, 'max_dive_deg': 90.0, 'min_turn_radius_m': 0.0,
             'min_altitude_m': 0.0}

#: The settings that are PlannerConfig fields.
PLANNER_SETTINGS = {s.name: s for s in SETTINGS if s.scope == 'planner'}
#: The node's parameters, in declaration order.
NODE_SETTINGS = {s.name: s for s in SETTINGS if s.node}


def _yaml_value(value: object) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return value if value else "''"
    if isinstance(value, list):
        return '[' + ', '.join(repr(float(v)) for v in value) + ']'
    text = repr(value)
    if isinstance(value, float) and 'e' in text and '.' not in text:
        # YAML 1.1 (PyYAML) reads 1e-06 as a string; 1.0e-06 is a float in every reader.
        mantissa, exponent = text.split('e')
        text = f'{mantissa}.0e{exponent}'
    return text


def params_file_text(node_name: str = 'threat_planner') -> str:
    """Return the node's parameters file: every default with its help, as in ``config/``.

    Parameters
    ----------
    node_name : str
        Node name heading the file.

    Returns
    -------
    str
        YAML text (what ``config/planner.yaml`` holds).

    """
    lines = [
        '# Default parameters of the threat_planner node (ROS 2 parameters file).',
        '# Use: ros2 run threat_planner planner_node --ros-args --params-file planner.yaml',
        f'# Every value can be changed at run time (ros2 param set /{node_name} w 0.7);',
        '# a bad value is refused with the reason. Generated from',
        '# threat_planner/core/inputs/settings.py (params_file_text); a test keeps them equal.',
        f'{node_name}:',
        '  ros__parameters:',
    ]
    for s in NODE_SETTINGS.values():
        text = s.doc + (f'; {s.span}' if s.span else '') + '.'
        lines.extend(textwrap.wrap(text, 92, initial_indent='    # ', subsequent_indent='    # '))
        lines.append(f'    {s.name}: {_yaml_value(s.default)}')
    return '\n'.join(lines) + '\n'
