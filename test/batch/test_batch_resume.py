"""Results survive: a run killed with SIGKILL, run again, gives the uninterrupted table."""

from pathlib import Path
import re
import signal
import subprocess
import sys
import time

import pyarrow.parquet as pq
import pytest
from study_harness import cli, descendants, ROOT, rows, write_study

from threat_planner.batch.runner import run_batch
from threat_planner.batch.store import Store
from threat_planner.batch.study import load_study
from threat_planner.batch.tasks import task_list
from threat_planner.errors import InputError

# 2 scenarios x 6 w x 2 settings = 24 plans, each scored on 8 pictures: a few seconds of
# work in chunks of about 3 plans.
STUDY = dict(w=[0.2, 0.3, 0.4, 0.5, 0.6, 0.7], settings={'max_climb_deg': [25, 30]},
             uncertainty={'samples': 8, 'position_sigma_m': 5.0, 'seed': 2})


@pytest.fixture(scope='module')
def study(tmp_path_factory):
    return write_study(tmp_path_factory.mktemp('study'), **STUDY)


@pytest.fixture(scope='module')
def whole(study, tmp_path_factory):
    """The uninterrupted run's table."""
    out = tmp_path_factory.mktemp('whole')
    run_batch(study, out, workers=2)
    return pq.read_table(out / 'results.parquet')


def test_killed_mid_run_then_resumed_equals_the_uninterrupted_table(study, whole, tmp_path):
    out = tmp_path / 'out'
    run = subprocess.Popen([sys.executable, '-m', 'threat_planner.cli', 'batch', str(study),
                            '--out', str(out), '--workers', '2'], cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not list((out / 'parts').glob('*.parquet')) and time.monotonic() < deadline:
        assert run.poll() is None, run.stderr.read().decode()
        time.sleep(0.005)
    workers = descendants(run.pid)
    run.send_signal(signal.SIGKILL)            # kill -9: no handler, no clean-up
    run.wait()
    run.stdout.close()
    run.stderr.close()
    assert not (out / 'results.parquet').exists(), 'the run ended before it was killed'
    assert workers, 'no worker process was running'
    # The orphaned workers notice and leave.
    deadline = time.monotonic() + 10
    while any(Path(f'/proc/{p}').exists() for p in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(Path(f'/proc/{p}').exists() for p in workers)
    again = cli('batch', study, '--out', out, '--workers', '2', cwd=ROOT)
    assert again.returncode == 0, again.stderr
    ran, before = map(int, re.search(r'(\d+) run now \((\d+) done before\)',
                                     again.stdout).groups())
    assert ran + before == 24 and ran > 0 and before > 0
    assert rows(pq.read_table(out / 'results.parquet')) == rows(whole)
    assert not list((out / 'parts').iterdir())     # merged and tidied
    third = cli('batch', study, '--out', out, '--workers', '2', cwd=ROOT)
    assert third.returncode == 0 and '24 tasks, 0 run now (24 done before)' in third.stdout
    assert rows(pq.read_table(out / 'results.parquet')) == rows(whole)


def _interrupted_run(study, out):
    """Run the study and SIGINT it once its first chunk is committed: (returncode, stderr)."""
    run = subprocess.Popen([sys.executable, '-m', 'threat_planner.cli', 'batch', str(study),
                            '--out', str(out), '--workers', '1'], cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while not list((out / 'parts').glob('*.parquet')) and run.poll() is None:
        time.sleep(0.005)
    run.send_signal(signal.SIGINT)
    _, stderr = run.communicate(timeout=120)
    return run.returncode, stderr


def test_ctrl_c_stops_the_run_and_the_same_command_resumes_it(study, whole, tmp_path):
    # One worker runs the chunks one after another, so the SIGINT lands with most of them
    # still to run. (A run that went on to exit 0 was a suite started with SIGINT ignored:
    # see test/conftest.py.)
    out = tmp_path / 'out'
    code, stderr = _interrupted_run(study, out)
    assert code == 130, stderr
    assert stderr.replace('\r', '\n').strip().splitlines()[-1] == 'threat-planner: interrupted'
    assert 'Traceback' not in stderr
    store = Store(out, load_study(study))
    done = len(store.done())
    store.close()
    assert 0 < done < 24, 'the interrupted run went on to the end'
    again = cli('batch', study, '--out', out, '--workers', '2', cwd=ROOT)
    assert again.returncode == 0, again.stderr
    assert f'{24 - done} run now ({done} done before)' in again.stdout
    assert rows(pq.read_table(out / 'results.parquet')) == rows(whole)


def test_merge_keeps_each_row_once_whatever_the_sources_hold(study, whole, tmp_path):
    """A crash between writing the table and removing its parts leaves rows twice."""
    tasks = task_list(load_study(study))
    store = Store(tmp_path, load_study(study))
    done = whole.to_pylist()
    half = [r for r in done if r['task'] in {t.key for t in tasks[:10]}]
    store.commit(half)
    store.commit(half)                              # the same rows in two parts
    store.merge(tasks)
    store.commit(half[:5])                          # and again beside the merged table
    (tmp_path / 'parts' / '.cut.parquet.1.tmp').write_bytes(b'PAR1 cut off')
    store.close()
    store = Store(tmp_path, load_study(study))      # removes the cut-off write
    assert not list((tmp_path / 'parts').glob('.*.tmp'))
    assert store.done() == {t.key for t in tasks[:10]}
    store.commit([r for r in done if r not in half])
    table = store.merge(tasks)
    store.close()
    assert rows(table) == rows(whole)


HOLD = ('import sys\n'
        'from threat_planner.batch.store import Store\n'
        'from threat_planner.batch.study import load_study\n'
        'store = Store(sys.argv[1], load_study(sys.argv[2]))\n'
        'print("held", flush=True)\n'
        'sys.stdin.read()\n')


def test_a_folder_in_use_or_of_another_study_is_refused(study, tmp_path):
    other_run = subprocess.Popen([sys.executable, '-c', HOLD, str(tmp_path), str(study)],
                                 cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 text=True)
    assert other_run.stdout.readline().strip() == 'held'
    with pytest.raises(InputError, match='another batch run is writing to'):
        Store(tmp_path, load_study(study))
    other_run.stdin.close()                          # that run ends: the folder is free
    assert other_run.wait(timeout=60) == 0
    other_run.stdout.close()
    Store(tmp_path, load_study(study)).close()
    other = Path(study).parent / 'other.yaml'
    other.write_text(Path(study).read_text().replace('- 0.7', '- 0.8'))
    with pytest.raises(InputError, match=r'holds the results of another study \(its w'):
        Store(tmp_path, load_study(other))
