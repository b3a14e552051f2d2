"""ProcessPlanWorker: plans in a child process, which is killed on timeout, cancel and stop."""

import threading
import time

from builtin_interfaces.msg import Time
import numpy as np
import pytest

from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan
from threat_planner.ros.outputs import PlanRequest
from threat_planner.ros.parameters import PARAMETER_DEFAULTS, settings_from_parameters
from threat_planner.ros.worker import CANCEL_STALE_AFTER_S, ProcessPlanWorker

from node_harness import REPO

SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')


def request(seq, **params):
    box = SCENARIO.box
    values = {**PARAMETER_DEFAULTS, 'bounds': box.lo.tolist() + box.hi.tolist(),
              'start': SCENARIO.start.tolist(), 'goal': SCENARIO.goal.tolist(), **params}
    s = settings_from_parameters(values)
    return PlanRequest(seq=seq, source='test', stamp=Time(sec=seq), received_ns=time.time_ns(),
                       threats=SCENARIO.threats, start=s.start, goal=s.goal, settings=s)


class Phases:
    def __init__(self):
        self.cond = threading.Condition()
        self.got = []

    def __call__(self, phase, outcome):
        with self.cond:
            self.got.append((phase, outcome))
            self.cond.notify_all()

    def wait(self, pred, timeout=60.0):
        with self.cond:
            assert self.cond.wait_for(lambda: any(pred(p, o) for p, o in self.got), timeout), \
                [(p, o.request.seq) for p, o in self.got]
            return next(o for p, o in self.got if pred(p, o))


def test_a_plan_in_the_child_equals_the_library_plan():
    phases = Phases()
    worker = ProcessPlanWorker(phases)
    try:
        req = request(1, method='paper')
        worker.submit(req)
        done = phases.wait(lambda p, o: p == 'done')
        assert [p for p, _ in phases.got] == ['paths', 'done']
        expected = plan(req.threats, req.start, req.goal, req.settings.box, req.settings.config)
        assert done.result.cost == expected.cost
        assert (done.result.path == expected.path).all()
        assert len(done.path.poses) == len(expected.path)
    finally:
        assert worker.stop()


def test_timeout_cancel_and_stop_kill_the_plan():
    phases = Phases()
    worker = ProcessPlanWorker(phases)
    try:
        # A 'best' plan of 5000 points takes far longer than 0.5 s.
        worker.submit(request(1, n_points=5000, max_plan_time_s=0.5))
        timed_out = phases.wait(lambda p, o: p == 'timeout')
        assert 'timed out after' in timed_out.error and 'max_plan_time_s=0.5' in timed_out.error
        # Timed from when the child took the request (not while a fresh child imports).
        assert 500.0 <= timed_out.plan_ms < 1500.0
        # The search had finished: its route is handed over as the best path so far.
        points = [[q.pose.position.x, q.pose.position.y, q.pose.position.z]
                  for q in timed_out.best_so_far.poses]
        assert points[0] == SCENARIO.start.tolist() and points[-1] == SCENARIO.goal.tolist()
        ref = path_cost(np.array(points), SCENARIO.threats.positions,
                        SCENARIO.threats.intensities, 0.5)
        assert timed_out.best_so_far_cost.J == pytest.approx(ref.J, rel=1e-12)
        assert 'paths' not in [p for p, _ in phases.got]
        # A newer request cancels a long stale plan, and is planned itself.
        worker.submit(request(2, n_points=5000))
        time.sleep(0.2)
        worker.submit(request(3, method='paper'))
        cancelled = phases.wait(lambda p, o: p == 'cancelled')
        assert cancelled.request.seq == 2 and cancelled.plan_ms >= 1e3 * CANCEL_STALE_AFTER_S
        phases.wait(lambda p, o: p == 'done' and o.request.seq == 3)
        # Stop during a long plan returns at once.
        worker.submit(request(4, n_points=5000))
        time.sleep(0.5)
        assert worker.busy
        t0 = time.monotonic()
        assert worker.stop()
        assert time.monotonic() - t0 < 1.0
    finally:
        worker.stop()


def _watch_processes(monkeypatch):
    """Record every plan process made, and which of the earlier ones were ready then."""
    from threat_planner.ros import worker as module
    made, ready_then = [], []

    class Watched(module._PlanProcess):
        def __init__(self, held=False):
            ready_then.append([p.ready.is_set() for p in made])
            super().__init__(held)
            made.append(self)
    monkeypatch.setattr(module, '_PlanProcess', Watched)
    return made, ready_then


def _wait(condition, timeout=60.0):
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()


def test_the_spare_starts_only_once_a_plan_runs_long_enough_to_be_killed(monkeypatch):
    """Short plans run no spare (a process of numpy, scipy and the kernels less); a plan that
    has run SPARE_AFTER_RUNNING_S, or half its time limit, starts it, before the plan can be
    killed; a kill hands over to it, and the next spare starts at once."""
    made, ready_then = _watch_processes(monkeypatch)
    phases = Phases()
    worker = ProcessPlanWorker(phases)
    try:
        first = made[0]
        assert first.ready.wait(60.0)
        worker.submit(request(1, method='paper'))
        phases.wait(lambda p, o: p == 'done')
        time.sleep(0.5)
        assert len(made) == 1 and worker._spare is None
        # 5,000 points run for seconds: the spare starts 0.25 s in, the timeout is at 0.5 s.
        worker.submit(request(2, n_points=5000, max_plan_time_s=0.5))
        assert _wait(lambda: len(made) == 2)
        with phases.cond:
            assert 'timeout' not in [p for p, _ in phases.got]
        spare = made[1]
        assert ready_then[:2] == [[], [True]]
        assert worker._child is first and worker._spare is spare
        phases.wait(lambda p, o: p == 'timeout')
        # The spare took over, and a new spare is on its way at once.
        assert worker._child is spare and worker._spare is made[2] and len(made) == 3
        worker.submit(request(3, method='paper'))
        assert phases.wait(lambda p, o: p.startswith('done') and o.request.seq == 3)
    finally:
        assert worker.stop()
    assert all(p.proc.exitcode is not None for p in made)


def test_an_idle_worker_and_short_plans_run_no_spare(monkeypatch):
    made, _ = _watch_processes(monkeypatch)
    phases = Phases()
    worker = ProcessPlanWorker(phases)
    try:
        for seq in range(1, 4):
            worker.submit(request(seq, method='paper'))
            phases.wait(lambda p, o, seq=seq: p == 'done' and o.request.seq == seq)
        time.sleep(1.0)
        assert len(made) == 1 and worker._spare is None
    finally:
        assert worker.stop()


def test_a_prestarted_child_waits_for_the_worker_before_it_loads_the_kernels():
    """`planner_node` spawns its plan process before its own imports (ros/entry.py); the
    child loads the kernels only once the node's worker takes it, after a cold cache was
    compiled in the node; a child that died meanwhile is replaced."""
    from threat_planner.ros import worker as module
    module.prestart()
    held = module._PRESTARTED
    worker = None
    try:
        module.prestart()
        assert module._PRESTARTED is held and held.proc.is_alive()
        assert not held.ready.wait(2.0)          # imported by now, but held
        phases = Phases()
        worker = ProcessPlanWorker(phases)
        assert worker._child is held and module._PRESTARTED is None
        assert held.ready.wait(60.0)
        worker.submit(request(1, method='paper'))
        assert phases.wait(lambda p, o: p == 'done').request.seq == 1
    finally:
        if worker is not None:
            assert worker.stop()
        held.kill()
    module.prestart()
    dead = module._PRESTARTED
    dead.proc.kill()
    dead.proc.join(10.0)
    worker = ProcessPlanWorker(Phases())
    try:
        assert worker._child is not dead and worker._child.ready.wait(60.0)
    finally:
        assert worker.stop()
