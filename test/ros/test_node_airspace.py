"""The planner node in an airspace: no-fly zones and terrain on topics and from a file.

One node process (default 'best' settings, recording on) is fed over Fast DDS from this
process; each test publishes the zone set and terrain it needs (each message replaces the
previous one) and checks the node's plans against the exact airspace checks of the core.
"""

import signal
import subprocess

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from sensor_msgs.msg import Image, PointCloud2
from visualization_msgs.msg import Marker, MarkerArray
import yaml

from node_harness import (cloud, domain_id, info, planner_command, pose, PYTHON, REPO,
                          ros_env, RosClient, start_process, stop_process, VOLATILE)
from threat_planner.core.world.airspace import Airspace, make_zone
from threat_planner.core.world.terrain import Terrain
from threat_planner.ros.conversions import (image_from_terrain, path_from_msg, stamp_to_ns,
                                            zones_to_markers)
from threat_planner.ros.recording.bagfile import load_bag
from threat_planner.ros.recording.replay import replay_bag

DOMAIN = domain_id(45)
NS = '/air'
START, GOAL = [0.0, 0.0, 50.0], [100.0, 100.0, 50.0]   # the parameter defaults
THREATS = np.array([[20.0, 80.0, 50.0], [80.0, 20.0, 50.0], [20.0, 80.0, 20.0],
                    [80.0, 20.0, 80.0]])
F = np.full(4, 1.0e4)
PLAN_TIMEOUT = 120.0


class Node:
    """The node process and this process's publishers and subscriptions for it."""

    def __init__(self, client, params, log_path):
        self.client, self.log_path = client, log_path
        self.proc = start_process(planner_command(NS, params), DOMAIN, log_path)
        for name, kind in (('path', PathMsg), ('plan_info', DiagnosticArray),
                           ('network', MarkerArray)):
            client.subscribe(f'{NS}/{name}', kind)
        self.pubs = {'threats': client.publisher(f'{NS}/threats', PointCloud2),
                     'no_fly_zones': client.publisher(f'{NS}/no_fly_zones', MarkerArray),
                     'terrain': client.publisher(f'{NS}/terrain', Image),
                     'start': client.publisher(f'{NS}/start', PoseStamped, VOLATILE)}
        for pub in self.pubs.values():
            client.wait_matched(pub, timeout=30.0)
        self.stamp_s = 100

    def publish(self, topic, msg):
        self.pubs[topic].publish(msg)

    def stamp(self):
        self.stamp_s += 1
        return Time(sec=self.stamp_s)

    def infos(self):
        return [info(m) for _, m in list(self.client.messages[f'{NS}/plan_info'])]

    def answer(self, stamp, timeout=PLAN_TIMEOUT):
        """The plan_info answering the input stamped `stamp`, and its path if it planned."""
        ns = stamp_to_ns(stamp)
        msg = self.client.wait_for(f'{NS}/plan_info',
                                   lambda m: int(info(m)['input_stamp_ns']) == ns, timeout)
        i = info(msg)
        if i['level'] == 'ERROR':
            return i, None
        t0 = int(i['t0_ns'])   # the paths carry the plan's t0, not the input's stamp
        path = self.client.wait_for(f'{NS}/path',
                                    lambda m: stamp_to_ns(m.header.stamp) == t0, 10.0)
        return i, path_from_msg(path)

    def zones(self, *zones):
        stamp = self.stamp()
        self.publish('no_fly_zones', zones_to_markers(list(zones), 'map', stamp))
        return stamp

    def log(self):
        return self.log_path.read_text(errors='replace')


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'test_air_client')
    yield c
    c.close()


@pytest.fixture(scope='module')
def air_file(tmp_path_factory):
    path = tmp_path_factory.mktemp('airfile') / 'air.yaml'
    path.write_text(yaml.safe_dump({'no_fly_zones': [
        {'type': 'box', 'min': [40.0, 0.0, 0.0], 'max': [45.0, 30.0, 100.0]}]}))
    return path


@pytest.fixture(scope='module')
def node(client, tmp_path_factory, air_file):
    folder = tmp_path_factory.mktemp('airnode')
    n = Node(client, {'record': str(folder / 'run.mcap'), 'airspace_file': str(air_file),
                      'terrain_resolution': 10.0, 'terrain_clearance': 5.0},
             folder / 'node.log')
    n.recording = folder / 'run.mcap'
    stamp = n.stamp()
    n.publish('threats', cloud(THREATS, F, stamp=stamp))
    n.first = n.answer(stamp)
    yield n
    assert stop_process(n.proc, signal.SIGINT) == 0, n.log()


def test_the_file_zone_is_respected_from_the_start(node, air_file):
    i, path = node.first
    assert i['level'] == 'OK', i
    air = Airspace((make_zone('box', 'no_fly_zones[0]', min=[40, 0, 0], max=[45, 30, 100]),))
    assert air.violations(path) == []
    assert float(i['clearance_zones_m']) >= 0.0


def test_the_node_replans_around_a_zone_on_its_path(node):
    _, before = node.answer(node.zones())   # no zones: the topic replaced the file's
    middle = before[len(before) // 2]
    zone = make_zone('sphere', 'nfz[0]', center=middle, radius=12.0)
    assert Airspace((zone,)).violations(before), 'the zone must lie on the old path'
    i, after = node.answer(node.zones(zone))
    assert i['level'] == 'OK', i
    assert Airspace((zone,)).violations(after) == []
    assert float(i['clearance_zones_m']) >= 0.0
    shown = node.client.wait_for(f'{NS}/network', lambda m: any(
        k.ns == 'zones' and k.text == 'nfz[0]' for k in m.markers))
    sphere, = [k for k in shown.markers if k.ns == 'zones']
    assert sphere.type == Marker.SPHERE and sphere.scale.x == pytest.approx(24.0)


def test_a_start_inside_a_zone_is_refused_with_a_clear_error(node):
    node.answer(node.zones())
    paths = node.client.count(f'{NS}/path')
    i, path = node.answer(node.zones(make_zone('sphere', 'nfz[1]', center=START, radius=5)))
    assert path is None and i['level'] == 'ERROR'
    assert 'start: [0.0, 0.0, 50.0] is inside nfz[1] (sphere, 5 m deep)' in i['error']
    box = make_zone('box', 'nfz[2]', min=[60, 60, 0], max=[70, 70, 100])
    node.answer(node.zones(box))
    stamp = node.stamp()
    node.publish('start', pose([65.0, 65.0, 30.0], stamp=stamp))
    i, path = node.answer(stamp)
    assert path is None and 'start: [65.0, 65.0, 30.0] is inside nfz[2] (box' in i['error']
    assert f'{NS}/start rejected: start: [65.0, 65.0, 30.0] is inside nfz[2]' in node.log()
    assert node.client.count(f'{NS}/path') == paths + 1   # only the box's plan


def test_bad_zone_markers_are_refused_and_the_plan_kept(node):
    i0, _ = node.answer(node.zones())
    paths = node.client.count(f'{NS}/path')
    stamp = node.stamp()
    msg = zones_to_markers([make_zone('sphere', 'nfz[4]', center=[50, 50, 50], radius=5)],
                           'map', stamp)
    msg.markers[1].scale.x = msg.markers[1].scale.y = msg.markers[1].scale.z = -10.0
    node.publish('no_fly_zones', msg)
    i, path = node.answer(stamp)
    assert path is None and i['level'] == 'ERROR'
    assert i['error'] == 'nfz[4].radius: must be positive, got -5.0'
    assert node.client.count(f'{NS}/path') == paths and node.proc.poll() is None


def test_a_terrain_image_is_applied(node):
    node.answer(node.zones())
    heights = np.zeros((11, 11))
    heights[:, 4:7] = 70.0          # a ridge across the straight line, x = 40..60 m
    stamp = node.stamp()
    node.publish('terrain', image_from_terrain(Terrain.from_arrays([0, 0], 10, heights),
                                               'map', stamp))
    i, path = node.answer(stamp)
    assert i['level'] == 'OK', i
    # The node's grid parameters: resolution 10 m, clearance 5 m.
    terrain = Terrain.from_arrays([0, 0], 10.0, heights, clearance=5.0)
    assert Airspace((), terrain).violations(path) == []
    assert path[:, 2].max() >= 75.0 - 1e-9
    assert float(i['clearance_terrain_m']) >= 0.0
    network = node.client.wait_for(f'{NS}/network', lambda m: any(
        k.ns == 'terrain' for k in m.markers))
    surface, = [k for k in network.markers if k.ns == 'terrain']
    assert surface.type == Marker.TRIANGLE_LIST and len(surface.points) == 10 * 10 * 6
    stamp = node.stamp()
    node.publish('terrain', image_from_terrain(None, 'map', stamp))
    i, path = node.answer(stamp)   # an empty image removes the terrain
    assert i['level'] == 'OK' and 'clearance_terrain_m' not in i   # no airspace left


def test_a_bad_airspace_file_parameter_is_refused(node, tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'no_fly_zones': [{'type': 'prism', 'z_min': 0,
                                                     'z_max': 10, 'polygon': [
                                                         [0, 0], [10, 10], [10, 0], [0, 10]]}]}))
    result, = node.client.set_parameters(f'{NS}/threat_planner', {'airspace_file': str(bad)})
    assert not result.successful
    assert 'no_fly_zones[0].polygon: not a simple polygon' in result.reason
    assert '\n' not in result.reason


def test_replay_of_the_recorded_airspace_run_reproduces_its_plans(node):
    assert stop_process(node.proc, signal.SIGINT) == 0, node.log()
    bag = load_bag(node.recording)
    kinds = {i.kind for i in bag.inputs}
    assert {'threats', 'no_fly_zones', 'terrain', 'start'} <= kinds
    report = replay_bag(bag)
    assert report.ok, report.first_difference
    replayed = [r for r in report.rows if r.replayed == 'OK']
    rejected = [r for r in report.rows if r.replayed == 'rejected']
    assert len(replayed) >= 6 and len(rejected) >= 3


def test_a_node_started_with_a_bad_airspace_file_exits_with_the_reason(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'no_fly_zones': [{'type': 'cylinder', 'center': [5, 5],
                                                     'radius': 3, 'z_min': 10, 'z_max': 2}]}))
    log = tmp_path / 'node.log'
    proc = start_process(planner_command('/badair', {'airspace_file': str(bad)}), DOMAIN, log)
    assert proc.wait(60) == 1
    assert (f'cannot start: airspace_file {bad}: no_fly_zones[0].z_max: must exceed z_min '
            '(10.0), got 2.0') in log.read_text()


def test_live_replay_of_an_airspace_recording_drives_a_node_to_its_plan(client, tmp_path):
    bag = tmp_path / 'air.mcap'
    subprocess.run([PYTHON, '-m', 'threat_planner.cli', 'plan',
                    str(REPO / 'test' / 'data' / 'air_mixed_0.yaml'), '--record', str(bag)],
                   check=True, capture_output=True, cwd=REPO, timeout=300)
    ns = '/airlive'
    client.subscribe(f'{ns}/plan_info', DiagnosticArray)
    proc = start_process(planner_command(ns), DOMAIN, tmp_path / 'node.log')
    try:
        p = subprocess.run([PYTHON, '-m', 'threat_planner.cli', 'replay', str(bag), '--live',
                            '--rate', '4', '--namespace', ns], capture_output=True, text=True,
                           cwd=REPO, env=ros_env(DOMAIN), timeout=300)
        assert p.returncode == 0, p.stdout + p.stderr
        recorded = load_bag(bag).plans[-1]
        got = info(client.wait_for(f'{ns}/plan_info', lambda m: info(m)['level'] == 'OK'
                                   and int(info(m)['input_stamp_ns']) == recorded.stamp_ns,
                                   PLAN_TIMEOUT))
    finally:
        code = stop_process(proc)
    assert code == 0, (tmp_path / 'node.log').read_text()
    # The node got zones, terrain (with its grid parameters) and threats from the bag.
    assert float(got['J']) == pytest.approx(float(recorded.values['J']), rel=1e-12)
    assert float(got['clearance_terrain_m']) == pytest.approx(
        float(recorded.values['clearance_terrain_m']), rel=1e-9)
