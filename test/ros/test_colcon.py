"""Build the package with colcon into a temporary prefix and run the installed nodes.

This is what ``colcon build`` followed by ``ros2 run threat_planner planner_node`` does:
the node runs from ``install/threat_planner/lib/threat_planner/planner_node`` with the
environment of ``install/local_setup.sh`` and nothing from the source tree on its path.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest

from node_harness import domain_id, info, REPO, ros_env, RosClient, stop_process
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.ros.conversions import path_from_msg, stamp_to_ns
from threat_planner.ros.discovery import PROFILE_VARIABLES

DOMAIN = domain_id(46)
COLCON = Path(sys.executable).with_name('colcon')


@pytest.fixture(scope='module')
def install(tmp_path_factory):
    if not COLCON.exists() and shutil.which('colcon') is None:
        pytest.skip('colcon is not installed')
    colcon = str(COLCON) if COLCON.exists() else shutil.which('colcon')
    base = tmp_path_factory.mktemp('colcon')
    cmd = [colcon, '--log-base', str(base / 'log'), 'build', '--base-paths', str(REPO),
           '--build-base', str(base / 'build'), '--install-base', str(base / 'install'),
           '--event-handlers', 'console_direct+']
    # THREAT_PLANNER_AOT_BUILD=0: the AOT build is test_aot.py's (once in the suite).
    done = subprocess.run(cmd, cwd=str(base), capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL,
                          env=dict(os.environ, THREAT_PLANNER_AOT_BUILD='0'))
    assert done.returncode == 0, done.stdout + done.stderr
    (base / 'build_output.txt').write_text(done.stdout + done.stderr)
    return base / 'install'


def test_the_build_compiles_the_kernels_into_the_shared_cache(install):
    """setup.py's build step ran the kernels' workload (a warm cache: it only loads)."""
    output = (install.parent / 'build_output.txt').read_text()
    assert 'threat_planner: loaded' in output or 'threat_planner: compiled' in output, \
        output[-3000:]


def test_install_layout(install):
    pkg = install / 'threat_planner'
    for script in ('planner_node', 'threat_publisher', 'sim_vehicle'):
        assert os.access(pkg / 'lib' / 'threat_planner' / script, os.X_OK), script
    # package data: the discovery profile the executables load
    assert list(pkg.glob('lib/python*/site-packages/threat_planner/ros/fastdds_discovery.xml'))
    share = pkg / 'share' / 'threat_planner'
    for rel in ('package.xml', 'config/planner.yaml', 'launch/planner.launch.py',
                'launch/flight.launch.py', 'scenarios/uniform20_0.yaml'):
        assert (share / rel).is_file(), rel
    assert (install / 'share' / 'ament_index' / 'resource_index' / 'packages' /
            'threat_planner').is_file() or (
        pkg / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'threat_planner'
    ).is_file()


def run_installed(install, executable, ros_args, log_path, cwd):
    """Start an installed executable the way ``ros2 run`` would, from a sourced prefix."""
    env = ros_env(DOMAIN)
    # Only what local_setup.sh puts on the path: not the source tree.
    env.pop('PYTHONPATH', None)
    # No profile from the harness: the executable loads its installed one.
    for name in PROFILE_VARIABLES:
        env.pop(name, None)
    script = install / 'threat_planner' / 'lib' / 'threat_planner' / executable
    command = '. "$1/local_setup.sh" && shift && exec "$@"'
    log = open(log_path, 'wb')
    try:
        return subprocess.Popen(['sh', '-c', command, 'sh', str(install), str(script),
                                 '--ros-args'] + list(ros_args),
                                cwd=str(cwd), env=env, stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL)
    finally:
        log.close()


def test_sourced_prefix_imports_the_installed_package(install, tmp_path):
    # An editable install of the source tree in .venv must not shadow the built one.
    env = ros_env(DOMAIN)
    env.pop('PYTHONPATH', None)
    done = subprocess.run(
        ['sh', '-c', '. "$1/local_setup.sh" && exec "$2" -c "$3"', 'sh', str(install),
         sys.executable, 'import threat_planner.ros.node as m; print(m.__file__)'],
        cwd=str(tmp_path), env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().startswith(str(install)), done.stdout


def test_installed_planner_plans_published_scenario(install, tmp_path):
    share = install / 'threat_planner' / 'share' / 'threat_planner'
    scenario_file = share / 'scenarios' / 'uniform20_0.yaml'
    scenario = load_scenario(scenario_file)
    client = RosClient(DOMAIN, 'colcon_test_client')
    planner = publisher = None
    try:
        client.subscribe('/path', PathMsg)
        client.subscribe('/plan_info', DiagnosticArray)
        planner = run_installed(install, 'planner_node',
                                ['--params-file', str(share / 'config' / 'planner.yaml'),
                                 '-p', 'method:=paper'], tmp_path / 'planner.log', tmp_path)
        publisher = run_installed(install, 'threat_publisher',
                                  ['-p', f'scenario:={scenario_file}'],
                                  tmp_path / 'publisher.log', tmp_path)
        path = client.wait_for(
            '/path', lambda m: np.allclose(path_from_msg(m)[[0, -1]],
                                           [scenario.start, scenario.goal], atol=1e-9),
            timeout=60.0)
        assert len(path.poses) >= 2 and path.header.frame_id == 'map'
        t0 = stamp_to_ns(path.header.stamp)   # plan_info names the paths' t0
        plan_info = client.wait_for('/plan_info',
                                    lambda m: int(info(m).get('t0_ns', -1)) == t0, 10.0)
        assert info(plan_info)['threats'] == '20'
        assert planner.poll() is None and publisher.poll() is None
    finally:
        codes = [stop_process(p) for p in (publisher, planner) if p is not None]
        client.close()
    logs = (tmp_path / 'planner.log').read_text() + (tmp_path / 'publisher.log').read_text()
    assert codes == [0, 0], logs
    # Both loaded the installed discovery profile, and Fast DDS parsed it.
    assert logs.count('DDS discovery: announcing every 0.25 s') == 2, logs
    assert 'XMLPARSER' not in logs, logs
