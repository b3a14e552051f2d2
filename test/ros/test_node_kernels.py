"""The node makes its kernels ready at start-up and says so when it had to compile.

A cache that lacks some kernels (here: the network's, deleted from a copy of this
machine's cache) stands for a first start after an install that did not compile them.
"""

import shutil
import signal

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import PointCloud2

from node_harness import cloud, domain_id, info, planner_command, REPO, RosClient, \
    start_process, stop_process
from threat_planner.core import _numba_cache
from threat_planner.core.compiled import ensure_compiled
from threat_planner.core.inputs.scenario import load_scenario

SCENARIO = load_scenario(REPO / 'test' / 'data' / 'weak20_0.yaml')
PARAMS = {'start': SCENARIO.start.tolist(), 'goal': SCENARIO.goal.tolist(),
          'bounds': SCENARIO.box.lo.tolist() + SCENARIO.box.hi.tolist()}


def _start_and_plan(domain: int, log, seconds: float = 120.0) -> dict:
    proc = start_process(planner_command('/kernels', PARAMS), domain, log)
    client = RosClient(domain, 'kernels_client')
    try:
        client.subscribe('/kernels/plan_info', DiagnosticArray)
        pub = client.publisher('/kernels/threats', PointCloud2)
        client.wait_matched(pub, timeout=seconds)
        pub.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities))
        return info(client.wait_for('/kernels/plan_info', timeout=seconds))
    finally:
        client.close()
        assert stop_process(proc, signal.SIGTERM) == 0


def test_a_compile_at_start_up_is_one_info_line_and_the_next_start_has_none(
        tmp_path, monkeypatch):
    ensure_compiled()   # this machine's cache is complete, to be copied
    digest = _numba_cache.sources_digest()
    cache = tmp_path / 'cache'
    shutil.copytree(_numba_cache.cache_dir(), cache / digest)
    shutil.rmtree(cache / digest / 'network')
    (cache / digest / 'signatures.pickle').unlink()
    monkeypatch.setenv('THREAT_PLANNER_CACHE_DIR', str(cache))
    monkeypatch.setenv('THREAT_PLANNER_AOT', '0')  # the JIT cache's start-up compile
    domain = domain_id(171, span=20)

    first = _start_and_plan(domain, tmp_path / 'first.log')
    log = (tmp_path / 'first.log').read_text()
    compiled = [line for line in log.splitlines() if 'kernels: compiled' in line]
    assert len(compiled) == 1 and '[INFO]' in compiled[0], log
    assert first['level'] == 'OK' and float(first['J']) > 0
    assert list((cache / digest / 'network').glob('*.nbi'))
    # the ready line comes after the kernels: no input could have waited on the compile
    assert log.index('kernels: compiled') < log.index('ready:'), log

    second = _start_and_plan(domain, tmp_path / 'second.log')
    log2 = (tmp_path / 'second.log').read_text()
    assert 'kernels: compiled' not in log2, log2
    assert second['J'] == first['J']
