"""Both backends run the same tasks with the same seeds into the same table."""

import os
from pathlib import Path
import signal
import threading
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
from study_harness import descendants, rows, write_study

from threat_planner import load_scenario, path_cost
from threat_planner.batch.runner import run_batch
from threat_planner.batch.study import load_study
from threat_planner.batch.tasks import task_list
from threat_planner.core.robust import sample_pictures, Uncertainty

SAMPLES = 3
STUDY = dict(w=[0.3, 0.7], method=['best'], settings={'max_climb_deg': 25},
             uncertainty={'samples': SAMPLES, 'position_sigma_m': 5.0,
                          'intensity_sigma': 0.2, 'seed': 4},
             robust={'samples': 2})


@pytest.fixture(scope='module')
def study(tmp_path_factory):
    return write_study(tmp_path_factory.mktemp('study'), **STUDY)


@pytest.fixture(scope='module')
def local_table(study, tmp_path_factory):
    out = tmp_path_factory.mktemp('local')
    run = run_batch(study, out, workers=2)
    assert run.ran == run.tasks == 8 and run.errors == 0
    return pq.read_table(out / 'results.parquet')


def test_the_table_holds_one_row_per_task_and_sample_in_task_order(study, local_table):
    tasks = task_list(load_study(study))
    got = local_table.to_pylist()
    assert len(got) == len(tasks) * (1 + SAMPLES)
    assert [(r['task'], r['sample']) for r in got] == \
        [(t.key, s) for t in tasks for s in [None, *range(SAMPLES)]]
    assert set(local_table.column_names) >= {
        'scenario', 'w', 'method', 'max_climb_deg', 'plan', 'sample', 'J', 'J_L', 'J_R',
        'feasible', 'total_ms', 'path'}
    assert {r['plan'] for r in got} == {'nominal', 'robust'}


def test_every_j_is_the_exact_j_of_the_saved_path(study, local_table):
    """Recomputed from the library alone: the path on the nominal and sampled pictures."""
    folder = Path(study).parent
    by_task = {}
    for r in local_table.to_pylist():
        by_task.setdefault(r['task'], []).append(r)
    tasks = {t.key: t for t in task_list(load_study(study))}
    for key, (head, *samples) in by_task.items():
        t = tasks[key]
        sc = load_scenario(folder / head['scenario'])
        path = np.array(head['path'])
        assert path.shape == (41, 3)
        nominal = path_cost(path, sc.threats.positions, sc.threats.intensities, head['w'])
        assert head['J'] == pytest.approx(nominal.J, rel=1e-12)
        assert head['total_ms'] > 0 and head['feasible']
        pictures = sample_pictures(sc.threats, SAMPLES, Uncertainty(5.0, 0.2),
                                   t.evaluation_seed)
        for r, pic in zip(samples, pictures):
            exact = path_cost(path, pic.positions, pic.intensities, r['w'])
            assert r['J'] == pytest.approx(exact.J, rel=1e-12)
            assert r['path'] is None and r['total_ms'] is None
        if head['plan'] == 'robust':
            own = sample_pictures(sc.threats, 2, Uncertainty(5.0, 0.2), t.robust_seed,
                                  antithetic=True)
            mean = np.mean([path_cost(path, p.positions, p.intensities, r['w']).J
                            for p in own])
            assert head['J_planned'] == pytest.approx(mean, rel=1e-12)


def test_one_worker_gives_the_same_table(study, local_table, tmp_path):
    run_batch(study, tmp_path, workers=1)
    assert rows(pq.read_table(tmp_path / 'results.parquet')) == rows(local_table)


# ---- Ray: a real local cluster, started here -----------------------------------------

def _ray():
    ray = pytest.importorskip('ray', reason="Ray is not installed (pip install "
                                            "'threat_planner[cluster]')")
    try:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    except Exception as exc:  # noqa: BLE001 - any reason Ray cannot start here
        pytest.skip(f'a local Ray cluster cannot start here: {exc}')
    return ray


@pytest.fixture(scope='module')
def ray_cluster():
    ray = _ray()
    yield ray
    ray.shutdown()


def test_ray_gives_the_same_table(study, local_table, ray_cluster, tmp_path):
    run = run_batch(study, tmp_path, ray='auto')
    assert run.backend == 'ray (auto)' and run.ran == 8
    assert rows(pq.read_table(tmp_path / 'results.parquet')) == rows(local_table)


def _kill_a_running_chunk(found: list, stop: threading.Event) -> None:
    """SIGKILL the first of this test's Ray workers seen running a chunk."""
    while not stop.is_set():
        for pid in descendants(os.getpid()):
            try:
                title = Path(f'/proc/{pid}/cmdline').read_bytes()
            except OSError:
                continue
            if title.startswith(b'ray::run_chunk'):
                time.sleep(0.05)   # well into its chunk
                os.kill(pid, signal.SIGKILL)
                found.append(pid)
                return
        time.sleep(0.01)


def test_a_ray_worker_killed_mid_chunk_is_retried_without_a_duplicate_row(
        study, local_table, ray_cluster, tmp_path):
    killed: list[int] = []
    stop = threading.Event()
    killer = threading.Thread(target=_kill_a_running_chunk, args=(killed, stop))
    killer.start()
    try:
        run = run_batch(study, tmp_path, ray='auto')
    finally:
        stop.set()
        killer.join()
    assert killed, 'no Ray worker was seen running a chunk'
    table = pq.read_table(tmp_path / 'results.parquet')
    keys = [(r['task'], r['sample']) for r in table.to_pylist()]
    assert len(keys) == len(set(keys)) == run.rows
    assert rows(table) == rows(local_table)
