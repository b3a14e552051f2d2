"""Flight bags: ``fly --record`` and ``replay`` of a flight (issue 44 item 5).

The two regression flights of ``test/data/bags/`` (``flight_bags.py`` records them) open
in the project's reader, in rosbags and in mcap_ros2, hold the node's topics, and replay
within tolerance; a tampered copy does not. A flight recorded twice is the same bytes.
"""

from collections import Counter
import json
from pathlib import Path
import shutil

from mcap.reader import make_reader
import numpy as np
import pytest

from flight_bags import BAGS, FLIGHTS, MAX_BYTES, record, REPO, replay
from threat_planner.bag import McapRecorder, read_messages, read_ros_messages
from threat_planner.ros.interface import INPUT_TOPICS, OUTPUT_TOPICS
from threat_planner.ros.recording.flight_record import FLIGHT_FORMAT, is_flight_bag
from threat_planner.ros.recording.flight_replay import load_flight

NAMES = sorted(FLIGHTS)
RERECORD = '.venv/bin/python test/ros/flight_bags.py'
TOPICS = {
    '/threats': 'sensor_msgs/msg/PointCloud2', '/path': 'nav_msgs/msg/Path',
    '/odom': 'nav_msgs/msg/Odometry', '/plan_info': 'diagnostic_msgs/msg/DiagnosticArray',
    '/events': 'std_msgs/msg/String', '/flight_setup': 'std_msgs/msg/String',
    '/flight_result': 'std_msgs/msg/String', '/goal_pose': 'geometry_msgs/msg/PoseStamped',
    '/start': 'geometry_msgs/msg/PoseStamped',
    '/parameter_events': 'rcl_interfaces/msg/ParameterEvent',
}


def channels(path):
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    return {c.topic: (summary.schemas[c.schema_id].name, c.metadata['offered_qos_profiles'])
            for c in summary.channels.values()}


def one_line_error(p, needle):
    assert p.returncode == 2, (p.returncode, p.stdout, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], p.stderr


@pytest.mark.parametrize('name', NAMES)
def test_flight_bag_is_small_and_opens_in_every_reader(name):
    bag = BAGS / f'{name}.mcap'
    assert bag.is_file(), f'{bag} is missing: run {RERECORD}'
    assert bag.stat().st_size < MAX_BYTES
    assert is_flight_bag(bag)
    ours = list(read_messages(bag))
    counts = Counter(m.topic for m in ours)
    assert {t for t in TOPICS if t != '/no_fly_zones'} <= set(counts)
    assert {m.topic: m.type_name for m in ours} == {t: TOPICS[t] for t in counts}
    assert counts['/path'] == counts['/plan_info'] >= 4
    assert counts['/odom'] > 100 and counts['/events'] >= 3
    # The node's topic types and QoS where the node has the topic.
    node = channels(BAGS / 'uniform20.mcap')
    mine = channels(bag)
    for topic in ('/threats', '/path', '/plan_info', '/goal_pose', '/start'):
        assert mine[topic] == node[topic], topic
    odom_type, _ = INPUT_TOPICS['odom']
    assert mine['/odom'][0] == odom_type and OUTPUT_TOPICS['path'][0] == mine['/path'][0]

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        decoded = [reader.deserialize(raw, con.msgtype) for con, _, raw in reader.messages()]
    assert len(decoded) == len(ours)
    mcap_ros2 = pytest.importorskip('mcap_ros2.decoder')
    with open(bag, 'rb') as f:
        n = sum(1 for _ in make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
                .iter_decoded_messages())
    assert n == len(ours)


@pytest.mark.parametrize('name', NAMES)
def test_flight_bag_replays_within_tolerance(name):
    bag = BAGS / f'{name}.mcap'
    p = replay(bag)
    assert p.returncode == 0, (
        f'threat-planner fly no longer reproduces test/data/bags/{name}.mcap:\n{p.stdout}'
        f'{p.stderr}\nIf the flight changed on purpose, re-record with `{RERECORD}`.')
    lines = p.stdout.strip().splitlines()
    plans = len(load_flight(bag).plans)
    assert len(lines) == plans + 1 and all(line.endswith(': ok') for line in lines[:-1])
    assert 'flight replayed, all within tolerance 1e-06' in lines[-1]
    assert 'reached_goal True -> True' in lines[-1]


def test_flight_bag_holds_the_flight_as_the_node_would(tmp_path):
    """Stamps are flight time; paths are stamped trajectories; the picture moves."""
    bag = BAGS / 'flight_moving.mcap'
    msgs = list(read_ros_messages(bag))
    by = {}
    for m in msgs:
        by.setdefault(m.topic, []).append(m)
    setup = json.loads(by['/flight_setup'][0].msg.data)
    assert setup['format'] == FLIGHT_FORMAT
    epoch = setup['epoch_ns']
    assert by['/flight_setup'][0].log_time_ns == epoch
    events = [json.loads(m.msg.data) for m in by['/events']]
    assert [e['t'] for e in events] == [1.0, 2.0, 3.0]
    assert events == setup['events']
    assert [m.log_time_ns for m in by['/events']] == [epoch + 10 ** 9 * k for k in (1, 2, 3)]
    # moving threats: clouds with velocities, at least every 0.5 s while they move
    clouds = by['/threats']
    assert [f.name for f in clouds[-1].msg.fields] == ['x', 'y', 'z', 'intensity', 'vx', 'vy',
                                                       'vz']
    gaps = np.diff([m.log_time_ns for m in clouds if m.log_time_ns > epoch + 10 ** 9])
    assert len(clouds) > 10 and gaps.max() <= 0.5e9 + 1
    assert clouds[-1].msg.width == 21
    for p, info in zip(by['/path'], by['/plan_info']):
        values = {kv.key: kv.value for kv in info.msg.status[0].values}
        t0 = int(values['t0_ns'])
        stamps = [pose.header.stamp.sec * 10 ** 9 + pose.header.stamp.nanosec
                  for pose in p.msg.poses]
        header = p.msg.header.stamp.sec * 10 ** 9 + p.msg.header.stamp.nanosec
        assert header == t0 == p.log_time_ns == info.log_time_ns
        assert stamps[0] == t0 and np.all(np.diff(stamps) > 0)
        assert abs(stamps[-1] - t0 - 1e9 * float(values['eta_s'])) < 2
        assert {'plan', 'plan_reason', 'J', 'replan_J', 'rounds', 'speed_mps'} <= set(values)
        assert 'plan_wall_ms' not in values    # recorded with --record-no-latency
    odom = by['/odom']
    dt = np.diff([m.log_time_ns for m in odom])
    assert odom[0].log_time_ns == epoch and np.all(dt[:-1] == 50_000_000)
    assert odom[0].msg.child_frame_id == 'base_link' and odom[0].msg.header.frame_id == 'map'
    result = json.loads(by['/flight_result'][0].msg.data)
    assert by['/flight_result'][0].log_time_ns == odom[-1].log_time_ns
    assert result['reached_goal'] is True and result['plans'] == len(by['/plan_info'])


def test_a_flight_recorded_twice_is_the_same_bytes(tmp_path):
    a, b = tmp_path / 'a' / 'flight.mcap', tmp_path / 'b' / 'flight.mcap'
    for target in (a, b):
        p = record('flight_popup', target)
        assert p.returncode == 0, p.stderr
        assert f'recorded: {target}' in p.stdout
    assert a.read_bytes() == b.read_bytes()
    # With the latencies (the default) it differs in them only, and still replays.
    c = tmp_path / 'c.mcap'
    p = record('flight_popup', c, latency=True)
    assert p.returncode == 0, p.stderr
    info = [m for m in read_messages(c) if m.topic == '/plan_info']
    assert all(any(kv.key == 'plan_wall_ms' for kv in m.msg.status[0].values) for m in info)
    p = replay(c)
    assert p.returncode == 0, p.stdout + p.stderr


def _copy(src: Path, dst: Path, change) -> None:
    """Write `src` again into `dst`, every message through ``change(topic, index, msg)``."""
    topics = {}
    with McapRecorder(dst, flush_interval_s=None) as rec:
        for m in read_ros_messages(src):
            if m.topic not in topics:
                rec.add_topic(m.topic, m.type_name)
                topics[m.topic] = 0
            msg = change(m.topic, topics[m.topic], m.msg)
            topics[m.topic] += 1
            if msg is not None:     # None: dropped
                rec.write(m.topic, msg, log_time_ns=m.log_time_ns)


def test_a_tampered_flight_bag_fails_the_replay(tmp_path):
    def moved(topic, index, msg):
        if topic == '/path' and index == 2:
            msg.poses[5].pose.position.z += 1.0
        return msg
    bad = tmp_path / 'tampered.mcap'
    _copy(BAGS / 'flight_popup.mcap', bad, moved)
    p = replay(bad)
    assert p.returncode == 1, p.stdout + p.stderr
    assert 'REGRESSION' in p.stdout
    assert 'first difference: plan 3 at t=2.50 s: path points moved up to 1 m' in p.stdout
    # A looser tolerance lets the moved point through.
    assert replay(bad, '--tolerance', '1.5').returncode == 0


def test_a_flight_bag_with_another_result_fails(tmp_path):
    def result(topic, index, msg):
        if topic == '/flight_result':
            data = json.loads(msg.data)
            data['reached_goal'] = False
            msg.data = json.dumps(data)
        return msg
    bad = tmp_path / 'result.mcap'
    _copy(BAGS / 'flight_moving.mcap', bad, result)
    p = replay(bad)
    assert p.returncode == 1 and 'reached_goal False -> True' in p.stdout, p.stdout


def test_bad_flight_bags_exit_2_with_one_line(tmp_path):
    def unknown(topic, index, msg):
        if topic == '/flight_setup':
            msg.data = json.dumps({**json.loads(msg.data), 'format': 'flight 99'})
        return msg
    bad = tmp_path / 'format.mcap'
    _copy(BAGS / 'flight_popup.mcap', bad, unknown)
    one_line_error(replay(bad), "/flight_setup.format: expected 'threat_planner flight 1'")
    cut = tmp_path / 'cut.mcap'
    shutil.copyfile(BAGS / 'flight_popup.mcap', cut)
    cut.write_bytes(cut.read_bytes()[:20_000])
    one_line_error(replay(cut), 'cut.mcap')
    one_line_error(replay(BAGS / 'flight_popup.mcap', '--live'), '--live:')
    unfinished = tmp_path / 'unfinished.mcap'
    _copy(BAGS / 'flight_popup.mcap', unfinished,
          lambda topic, index, msg: None if topic == '/flight_result' else msg)
    one_line_error(replay(unfinished), 'no /flight_result: the flight did not finish')


def test_replay_with_other_settings_differs():
    p = replay(BAGS / 'flight_moving.mcap', '--w', '0.3')
    assert p.returncode == 1 and 'REGRESSION' in p.stdout
    assert 'first difference: plan 1 at t=0.00 s: path' in p.stdout, p.stdout


def test_the_observer_changes_nothing_and_events_round_trip():
    """fly() flies the same with a recorder watching; an event's JSON parses back to it."""
    from threat_planner.core.inputs.config import PlannerConfig
    from threat_planner.core.inputs.scenario import load_scenario
    from threat_planner.flight.events import load_events, parse_events
    from threat_planner.flight.fly import fly
    from threat_planner.ros.recording.flight_record import event_mapping
    from threat_planner.ros.recording.flight_replay import _Collector
    scenario, events_file = FLIGHTS['flight_moving']
    sc = load_scenario(REPO / scenario)
    events = load_events(REPO / events_file)
    cfg = PlannerConfig(method='paper')
    watcher = _Collector()
    alone = fly(sc, events, cfg, 20.0, hindsight=False)
    watched = fly(sc, events, cfg, 20.0, hindsight=False, observer=watcher)
    assert np.array_equal(alone.path, watched.path) and alone.flown.J == watched.flown.J
    assert len(watcher.plans) == len(alone.replans) == 4
    assert all(p is not None and len(p) > 2 for _, p in watcher.plans)
    zone = {'t': 1.0, 'add_zone': {'type': 'sphere', 'center': [50.0, 50.0, 70.0],
                                   'radius': 8.0}}
    for listed in (events, parse_events({'events': [zone]})):
        doc = json.loads(json.dumps({'events': [event_mapping(e) for e in listed]}))
        again = parse_events(doc)
        assert [event_mapping(e) for e in again] == doc['events']
        assert [(e.t, e.kind, e.label) for e in again] == [(e.t, e.kind, e.label)
                                                           for e in listed]
    assert doc['events'][0] == zone


def test_fly_record_refuses_an_unwritable_target(tmp_path):
    blocker = tmp_path / 'file'
    blocker.write_text('')
    p = record('flight_popup', blocker / 'x.mcap')
    one_line_error(p, 'cannot create recording')
    assert REPO.is_dir()
