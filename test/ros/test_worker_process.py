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


def test_the_spare_starts_once_the_first_child_has_its_kernels(monkeypatch):
    """Started with the first child, the spare's imports competed with the first child's
    (and the node's) on two cores; it starts once the first child is ready, and a kill
    still hands over to it."""
    from threat_planner.ros import worker as module
    made, ready_then = [], []

    class Watched(module._PlanProcess):
        def __init__(self):
            ready_then.append([p.ready.is_set() for p in made])
            super().__init__()
            made.append(self)
    monkeypatch.setattr(module, '_PlanProcess', Watched)
    phases = Phases()
    worker = ProcessPlanWorker(phases)
    try:
        deadline = time.monotonic() + 60.0
        while len(made) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        first, spare = made[:2]
        assert ready_then[:2] == [[], [True]]
        assert worker._child is first and worker._spare is spare
        worker.submit(request(1, n_points=5000, max_plan_time_s=0.5))
        phases.wait(lambda p, o: p == 'timeout')
        # The loaded spare took over, and a new spare is on its way at once.
        assert worker._child is spare and worker._spare is made[2] and len(made) == 3
        worker.submit(request(2, method='paper'))
        assert phases.wait(lambda p, o: p == 'done').request.seq == 2
    finally:
        assert worker.stop()
    assert all(p.proc.exitcode is not None for p in made)
