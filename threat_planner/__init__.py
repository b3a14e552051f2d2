"""Threat-aware 3-D UAV path planning after Qu, Zhang and Zhang (Delaunay incentre network).

The public API: :func:`plan` a path through a :class:`ThreatField` inside a :class:`Box`
with a :class:`PlannerConfig`, getting a :class:`PlanResult`; :func:`load_scenario` reads a
scenario file. Sub-packages: ``core`` (the method, no ROS), ``ros`` (the node and message
conversions), ``bag`` (MCAP recording and replay), ``cli`` (``threat-planner``).
"""

from threat_planner.core import (Box, Cost, load_scenario, path_cost, plan, PlannerConfig,
                                 PlanResult, Scenario, ThreatField)
from threat_planner.errors import (InputError, PlanningError, RecordingError, ScenarioError,
                                   ThreatPlannerError)

__all__ = ['Box', 'Cost', 'InputError', 'PlanResult', 'PlannerConfig', 'PlanningError',
           'RecordingError', 'Scenario', 'ScenarioError', 'ThreatField', 'ThreatPlannerError',
           'load_scenario', 'path_cost', 'plan']
