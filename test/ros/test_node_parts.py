"""Tests of the planner node's parts that need no running node.

The parameters (config/planner.yaml, refused values), the plan worker's one-pending
queue, the threat publisher's drift and the launch file.
"""

import math
import py_compile
import threading
import time

import numpy as np
import pytest

from node_fixtures import SCENARIO, yaml_parameters
from node_harness import REPO
from threat_planner.core.planner import PlannerConfig
from threat_planner.errors import InputError
from threat_planner.ros.parameters import PARAMETER_DEFAULTS, settings_from_parameters
from threat_planner.ros.publisher import ThreatDrift
from threat_planner.ros.worker import PlanWorker


def test_config_file_holds_the_node_defaults():
    assert yaml_parameters() == PARAMETER_DEFAULTS
    defaults = PlannerConfig()
    for name in ('w', 'method', 'k', 'auto_k', 'damping', 'mass', 'q', 'n_points',
                 'max_pitch_deg', 'max_turn_deg', 'entry_candidates', 'confine_to_box'):
        assert PARAMETER_DEFAULTS[name] == getattr(defaults, name), name


@pytest.mark.parametrize('change, reason', [
    ({'w': 0.0}, 'w: must satisfy 0 < w < 1'),
    ({'method': 'fastest'}, 'method: must be one of'),
    ({'bounds': [0.0, 0.0, 0.0, 1.0, 1.0]}, 'bounds: expected 6 numbers'),
    ({'bounds': [0.0, 0.0, 0.0, 1.0, -1.0, 1.0]}, 'bounds: max.y must exceed min.y'),
    ({'start': [0.0, math.nan, 0.0]}, 'start: not finite'),
    ({'goal': [1.0, 2.0]}, 'goal: expected [x, y, z], got 2 values'),
    ({'frame_id': ''}, 'frame_id: must be a non-empty string'),
    ({'default_intensity': 0.0}, 'default_intensity: must be finite and > 0'),
    ({'max_threats': -1}, 'max_threats: must be an integer >= 0'),
])
def test_settings_refuse_bad_values(change, reason):
    with pytest.raises(InputError, match=reason.replace('[', r'\[').replace(']', r'\]')):
        settings_from_parameters({**PARAMETER_DEFAULTS, **change})


def test_settings_accept_integer_arrays():
    s = settings_from_parameters({**PARAMETER_DEFAULTS, 'bounds': [0, 0, 0, 10, 10, 10]})
    assert s.box.hi.tolist() == [10.0, 10.0, 10.0]


def test_plan_worker_runs_one_job_and_keeps_one_pending():
    release = threading.Event()
    started, done = [], []

    def run(job):
        started.append(job)
        if job == 0:
            release.wait(5.0)
        done.append(job)

    worker = PlanWorker(run)
    assert worker.submit(0) is False
    deadline = time.monotonic() + 5.0
    while not worker.busy and time.monotonic() < deadline:
        time.sleep(0.001)
    skipped = [worker.submit(j) for j in range(1, 6)]
    assert skipped == [False, True, True, True, True]
    assert started == [0] and worker.has_pending
    release.set()
    while len(done) < 2 and time.monotonic() < deadline:
        time.sleep(0.001)
    assert done == [0, 5]
    assert worker.stop()


def test_threat_drift_is_deterministic_and_stays_in_bounds():
    lo, hi = SCENARIO.box.lo, SCENARIO.box.hi
    p0 = SCENARIO.threats.positions
    for mode in ('random_walk', 'sinusoid'):
        a = ThreatDrift(p0, lo, hi, 5.0, mode, seed=3)
        b = ThreatDrift(p0, lo, hi, 5.0, mode, seed=3)
        for tick in range(1, 40):
            pa, pb = a.at(tick * 0.5, 0.5), b.at(tick * 0.5, 0.5)
            np.testing.assert_array_equal(pa, pb)
            assert np.all(pa >= lo) and np.all(pa <= hi)
        assert np.max(np.linalg.norm(pa - p0, axis=1)) > 1.0
    still = ThreatDrift(p0, lo, hi, 0.0)
    np.testing.assert_array_equal(still.at(10.0, 1.0), p0)


@pytest.mark.parametrize('name', ['planner', 'flight'])
def test_launch_file_compiles(tmp_path, name):
    py_compile.compile(str(REPO / 'launch' / f'{name}.launch.py'),
                       cfile=str(tmp_path / f'{name}.launch.pyc'), doraise=True)
    try:
        import launch_ros  # noqa: F401
    except ImportError:
        pytest.skip('launch_ros is not installed: only compiled')
    import importlib.util
    spec = importlib.util.spec_from_file_location(f'{name}_launch',
                                                  REPO / 'launch' / f'{name}.launch.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.generate_launch_description().entities
