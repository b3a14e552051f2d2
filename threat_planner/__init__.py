"""Threat-aware 3-D UAV path planning after Qu, Zhang and Zhang (Delaunay incentre network).

The public API: :func:`plan` a path through a :class:`ThreatField` inside a :class:`Box`
with a :class:`PlannerConfig`, getting a :class:`PlanResult`; :func:`load_scenario` reads a
scenario file. Sub-packages: ``core`` (the method, no ROS), ``ros`` (the node and message
conversions), ``bag`` (MCAP recording and replay), ``cli`` (``threat-planner``).

The names from ``core`` load on first use (PEP 562): ``import threat_planner.ros.entry``
must not pay numpy's and scipy's imports, so a node's plan process can start first.
``__version__`` (``package.xml``'s, see :mod:`threat_planner._version`) loads the same way.
"""

from threat_planner._lazy import lazy_names
from threat_planner.errors import (InputError, PlanningError, RecordingError, ScenarioError,
                                   ThreatPlannerError)

__all__ = ['Box', 'Cost', 'InputError', 'PlanResult', 'PlannerConfig', 'PlanningError',
           'RecordingError', 'Scenario', 'ScenarioError', 'ThreatField', 'ThreatPlannerError',
           'load_scenario', 'path_cost', 'plan']

__getattr__, __dir__ = lazy_names(__name__, {
    **dict.fromkeys(('Box', 'Cost', 'PlanResult', 'PlannerConfig', 'Scenario', 'ThreatField',
                     'load_scenario', 'path_cost', 'plan'), 'threat_planner.core'),
    '__version__': 'threat_planner._version'}, [*__all__, '__version__'])
