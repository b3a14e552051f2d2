"""The planning method, free of ROS: numpy arrays in, numpy arrays out.

One folder per concern, each importing only the folders above it in this list:
:mod:`.world` (threats §3.1, box, zones, terrain), :mod:`.geo` (WGS84 datum and ENU
conversions, DEM terrain), :mod:`.inputs` (settings, PlannerConfig, scenario files),
:mod:`.cost` (J, eq. 15-17), :mod:`.network` (§3.2-3.3), :mod:`.optimise` (§3.4 smoothing,
L-BFGS, flight limits), :mod:`.methods` (paper, improved, best); then :mod:`.planner`
(``plan()``), :mod:`.result` and :mod:`.robust` (sampled threat pictures, ``plan_robust``).
Nothing here imports rclpy or a message package, and no
import runs back up this list (``test/test_layers.py`` checks both).
"""

from threat_planner._lazy import lazy_names
from threat_planner.core import _aot, _numba_cache

try:
    if _aot.module() is None:  # the AOT kernels need no numba (_aot)
        _numba_cache.import_numba()  # before any kernel module does (see import_numba)
except ImportError:  # pragma: no cover - numba is in install_requires
    pass

from threat_planner.core.cost.closed_form import Cost, path_cost
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario, Scenario
from threat_planner.core.inputs.settings import METHODS, SETTINGS, Setting
from threat_planner.core.result import PlanResult
from threat_planner.core.world.threats import Box, check_endpoints, ThreatField

_aot.install()  # every kernel module is loaded now: the AOT kernels go in their place

__all__ = ['Box', 'Cost', 'METHODS', 'PlanResult', 'PlannerConfig', 'SETTINGS', 'Scenario',
           'Setting', 'ThreatField', 'check_endpoints', 'load_scenario', 'path_cost', 'plan']

# plan() loads the network's scipy.spatial (a third of a second): a process that only
# reads threats and settings (the node's own, whose plans run in a child) never pays it.
__getattr__, __dir__ = lazy_names(__name__, {'plan': 'threat_planner.core.planner'}, __all__)
