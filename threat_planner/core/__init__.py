"""The planning method, free of ROS: numpy arrays in, numpy arrays out.

One module per stage of the paper: :mod:`.threats` (§3.1), :mod:`.cost` (eq. 15-17),
:mod:`.partition` (§3.2), :mod:`.search` (§3.3), :mod:`.smoothing` (§3.4, eq. 4-14),
:mod:`.optimisation` (beyond the paper); :mod:`.methods` holds the three methods,
:mod:`.planner` runs one, :mod:`.settings` declares every setting once, :mod:`.scenario`
reads scenario files. Nothing here imports rclpy or a message package (a test checks).
"""

from threat_planner.core import _numba_cache

try:
    _numba_cache.import_numba()  # before any kernel module does (see import_numba)
except ImportError:  # pragma: no cover - numba is in install_requires
    pass

from threat_planner.core.config import PlannerConfig
from threat_planner.core.cost import Cost, path_cost
from threat_planner.core.planner import check_endpoints, plan
from threat_planner.core.result import PlanResult
from threat_planner.core.scenario import load_scenario, Scenario
from threat_planner.core.settings import METHODS, SETTINGS, Setting
from threat_planner.core.threats import Box, ThreatField

__all__ = ['Box', 'Cost', 'METHODS', 'PlanResult', 'PlannerConfig', 'SETTINGS', 'Scenario',
           'Setting', 'ThreatField', 'check_endpoints', 'load_scenario', 'path_cost', 'plan']
