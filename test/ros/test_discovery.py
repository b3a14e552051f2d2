"""The executables' Fast DDS discovery profile: when it applies, and that Fast DDS takes it."""

import os
from pathlib import Path
import subprocess
import sys
import time

import pytest

from node_harness import domain_id, REPO, ros_env, stop_process
from threat_planner.ros.discovery import (apply_discovery_profile, discovery_profile_refusal,
                                          PROFILE, PROFILE_VARIABLES, SWITCH)

DOMAIN = domain_id(47)


def test_a_clean_environment_gets_the_profile_under_both_fast_dds_names(tmp_path):
    env = {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'}
    assert apply_discovery_profile(env, tmp_path) is None
    assert {env[name] for name in PROFILE_VARIABLES} == {str(PROFILE)}
    assert PROFILE.is_file()


@pytest.mark.parametrize('env, reason', [
    ({SWITCH: '0'}, f'{SWITCH}=0'),
    ({SWITCH: 'Off'}, f'{SWITCH}=Off'),
    ({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}, 'RMW_IMPLEMENTATION=rmw_cyclonedds_cpp'),
    ({'FASTRTPS_DEFAULT_PROFILES_FILE': '/etc/mine.xml'}, 'FASTRTPS_DEFAULT_PROFILES_FILE'),
    ({'FASTDDS_DEFAULT_PROFILES_FILE': '/etc/mine.xml'}, 'FASTDDS_DEFAULT_PROFILES_FILE'),
    ({'ROS_DISCOVERY_SERVER': '127.0.0.1:11811'}, 'ROS_DISCOVERY_SERVER'),
])
def test_the_users_choice_is_left_alone(tmp_path, env, reason):
    before = dict(env)
    assert reason in apply_discovery_profile(env, tmp_path)
    assert env == before


def test_a_default_profile_file_in_the_working_folder_is_left_alone(tmp_path):
    (tmp_path / 'DEFAULT_FASTRTPS_PROFILES.xml').write_text('<dds/>')
    env = {}
    assert 'DEFAULT_FASTRTPS_PROFILES.xml' in apply_discovery_profile(env, tmp_path)
    assert env == {}
    assert discovery_profile_refusal({SWITCH: '1'}, tmp_path.parent) is None


def test_a_missing_profile_file_is_not_set(tmp_path, monkeypatch):
    import threat_planner.ros.discovery as discovery
    monkeypatch.setattr(discovery, 'PROFILE', tmp_path / 'gone.xml')
    env = {}
    assert 'gone.xml is missing' in discovery.apply_discovery_profile(env, tmp_path)
    assert env == {}


def _participant_output(profile: Path) -> str:
    """Stderr and stdout of a process that brings up one participant with `profile`."""
    env = ros_env(DOMAIN)
    for name in PROFILE_VARIABLES:
        env[name] = str(profile)
    done = subprocess.run(
        [sys.executable, '-c', 'import rclpy; from rclpy.node import Node; rclpy.init(); '
         'Node("discovery_probe").destroy_node(); rclpy.shutdown(); print("up")'],
        env=env, capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr
    return done.stdout + done.stderr


def test_fast_dds_parses_the_profile_and_would_say_if_it_could_not(tmp_path):
    assert 'XMLPARSER' not in _participant_output(PROFILE)
    broken = tmp_path / 'broken.xml'
    text = PROFILE.read_text()
    broken.write_text(text.replace('<nanosec>250000000</nanosec>', '<nanosec>x</nanosec>'))
    assert broken.read_text() != text
    assert 'XMLPARSER' in _participant_output(broken)


def test_an_executable_says_it_runs_the_profile_unless_switched_off(tmp_path):
    for switch, expected in (('1', 1), ('0', 0)):
        command = [sys.executable, '-m', 'threat_planner.ros.publisher', '--ros-args', '-p',
                   f'scenario:={REPO / "test" / "data" / "uniform20_0.yaml"}']
        env = ros_env(DOMAIN)
        for name in PROFILE_VARIABLES:
            env.pop(name, None)
        env[SWITCH] = switch
        log = tmp_path / f'publisher_{switch}.log'
        with open(log, 'wb') as out:
            process = subprocess.Popen(command, env=env, cwd=str(tmp_path), stdout=out,
                                       stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 30.0
            while 'published once' not in log.read_text() and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            assert stop_process(process) == 0, log.read_text()
        text = log.read_text()
        assert 'published once' in text, text
        assert text.count('DDS discovery: announcing every 0.25 s') == expected, text
        assert 'XMLPARSER' not in text
    assert os.environ.get(SWITCH) is None
