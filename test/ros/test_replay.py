"""Recording runs and replaying them: ``plan --record``, ``replay`` and the regression bags.

The bags in ``test/data/bags/`` were recorded by the live node with
``bench/record_regression_bags.py``; replaying one re-plans every recorded input state and
compares with the recorded plans. The node tests here run the node as its own process, as
test_node.py does. test_recording.py kills a bare recorder with SIGKILL; here it is the
node that is killed mid-recording.
"""

import math
import signal
import subprocess
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from mcap.reader import make_reader
from mcap.writer import Writer
from nav_msgs.msg import Path as PathMsg
import pytest
from sensor_msgs.msg import PointCloud2

from node_harness import (cloud, domain_id, info, planner_command, pose, PYTHON, REPO, ros_env,
                          RosClient, start_process, stop_process, VOLATILE)
from threat_planner.bag import McapRecorder, read_messages
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.errors import RecordingError
from threat_planner.ros.recording.flight_record import is_flight_bag
from threat_planner.ros.recording.replay import load_bag, replay_bag

DOMAIN = domain_id(86, span=3)
DATA = REPO / 'test' / 'data'
BAGS = DATA / 'bags'
REGRESSION_BAGS = ('uniform20', 'ground', 'moving_uniform20')
RERECORD = '.venv/bin/python bench/record_regression_bags.py'
SCENARIO = load_scenario(DATA / 'uniform20_0.yaml')
NODE_TOPICS = ('threats', 'threat_poses', 'start', 'goal_pose', 'initial_path', 'path',
               'network', 'plan_info')
#: The airspace inputs (issue 12), newer than the committed node bags.
AIRSPACE_TOPICS = ('no_fly_zones', 'terrain')
#: The GNSS fix inputs (issue 26), newer still.
GEO_TOPICS = ('start_fix', 'goal_fix')
FLIGHT_TOPICS = ('odom',)   # issue 44


def cli(*args, env=None, timeout=300):
    return subprocess.run([PYTHON, '-m', 'threat_planner.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=REPO, env=env)


def one_line_error(p, needle):
    assert p.returncode == 2, (p.returncode, p.stdout, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], p.stderr
    assert 'Traceback' not in p.stderr


def channels(path):
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    return {c.topic: (summary.schemas[c.schema_id].name, c.metadata['offered_qos_profiles'],
                      c.metadata['topic_type_hash']) for c in summary.channels.values()}


# ------------------------------------------------------------- regression bags


def test_regression_bags_are_present_and_small():
    for name in REGRESSION_BAGS:
        bag = BAGS / f'{name}.mcap'
        assert bag.is_file(), f'{bag} is missing: run {RERECORD}'
        assert bag.stat().st_size < 1_000_000, bag


# Flight bags (fly --record) replay by flying again: test_flight_bag.py.
ALL_BAGS = sorted({f.stem for f in BAGS.glob('*.mcap') if not is_flight_bag(f)}
                  | set(REGRESSION_BAGS))


@pytest.mark.parametrize('name', ALL_BAGS)
def test_regression_bag_replays_to_the_recorded_plans(name):
    bag = load_bag(BAGS / f'{name}.mcap')
    assert bag.parameters_recorded and bag.plans
    report = replay_bag(bag)
    assert report.ok, (
        f'the planner no longer reproduces test/data/bags/{name}.mcap:\n{report.table()}\n'
        f'{report.summary()}\nIf the planner changed on purpose, re-record the bags with '
        f'`{RERECORD}` (see its docstring) and commit them.')
    assert len(report.rows) == len(bag.plans)


def test_moving_bag_holds_several_replans():
    bag = load_bag(BAGS / 'moving_uniform20.mcap')
    pictures = {p.stamp_ns for p in bag.plans if p.source == '/threats'}
    assert len(pictures) >= 5
    assert bag.parameters['method'] == 'paper'


def test_replay_with_other_settings_reports_the_first_difference(tmp_path):
    report = tmp_path / 'replay.md'
    p = cli('replay', BAGS / 'ground.mcap', '--method', 'paper', '--report', report)
    assert p.returncode == 1, p.stderr
    assert 'REGRESSION' in p.stdout and 'first difference: /path for input #1' in p.stdout
    text = report.read_text()
    assert "overrides: method='paper'" in text and 'DIFFERS' in text
    # A looser tolerance does not hide a changed node sequence.
    p = cli('replay', BAGS / 'uniform20.mcap', '--w', '0.2', '--tolerance', '100')
    assert p.returncode == 1 and 'initial path nodes' in p.stdout


# ------------------------------------------------------------- plan --record


def test_plan_record_replays_and_matches_the_node(tmp_path):
    out = tmp_path / 'plan.mcap'
    p = cli('plan', DATA / 'uniform20_0.yaml', '--record', out)
    assert p.returncode == 0, p.stderr
    assert f'recorded: {out}' in p.stdout
    p = cli('replay', out)
    assert p.returncode == 0, p.stdout + p.stderr
    assert '1 plan replayed, all within tolerance 1e-06' in p.stdout

    # Same topics, types and QoS as the live node's recording of the same scenario...
    node_bag = BAGS / 'uniform20.mcap'
    recorded = channels(out)
    node_channels = channels(node_bag)
    # The committed bags predate the airspace topics; re-recorded, they hold them too.
    assert {t: recorded[t] for t in node_channels} == node_channels
    assert set(recorded) == ({f'/{t}' for t in NODE_TOPICS + AIRSPACE_TOPICS + GEO_TOPICS
                              + FLIGHT_TOPICS}
                             | {'/parameter_events'})
    assert set(node_channels) <= set(recorded)
    # ...the same parameter set, inputs and plan_info keys (the node's message code).
    offline, node = load_bag(out), load_bag(node_bag)
    assert offline.parameters.keys() == node.parameters.keys()
    assert offline.parameters['method'] == node.parameters['method'] == 'best'
    assert sorted(i.kind for i in offline.inputs) == sorted(i.kind for i in node.inputs)
    # The committed bag predates the trajectory keys (issue 44) and the detection keys
    # (issue 43); the rest match in order.
    timed = ['t0_ns', 'speed_mps', 'eta_s', 'cost_model', 'P_detect', 'H', 'detection_top']
    assert set(timed) <= set(offline.plans[0].values)
    assert ([k for k in offline.plans[0].values if k not in timed]
            == [k for k in node.plans[0].values if k not in timed])
    assert offline.plans[0].values['input_source'] == '/threats'
    assert offline.plans[0].path.shape == node.plans[0].path.shape


# ------------------------------------------------------------------ bad bags


def _protobuf_schema(path):
    with open(path, 'wb') as f:
        writer = Writer(f)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('sensor_msgs/msg/PointCloud2', 'protobuf', b'\x0a')
        channel = writer.register_channel('/threats', 'cdr', schema)
        writer.add_message(channel, log_time=1, data=b'\x00\x01\x00\x00', publish_time=1)
        writer.finish()


def _unknown_type(path):
    with open(path, 'wb') as f:
        writer = Writer(f)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('foo_msgs/msg/Radar', 'ros2msg', b'float64 x\n')
        channel = writer.register_channel('/threats', 'cdr', schema)
        writer.add_message(channel, log_time=1, data=b'\x00\x01\x00\x00' + bytes(8),
                           publish_time=1)
        writer.finish()


def _no_threats(path):
    with McapRecorder(path) as rec:
        rec.write('/start', pose([1.0, 2.0, 3.0]), log_time_ns=1)


def _truncated(path):
    data = (BAGS / 'moving_uniform20.mcap').read_bytes()
    path.write_bytes(data[:len(data) // 2])


@pytest.mark.parametrize('make, needle', [
    (_truncated, 'truncated MCAP file'),
    (_protobuf_schema, "schema encoding 'protobuf'"),
    (_unknown_type, 'topic /threats is a foo_msgs/msg/Radar'),
    (_no_threats, 'no threat topic'),
    (lambda p: p.write_text('threats:\n  - {position: [1, 2, 3]}\n' * 10), 'not an MCAP file'),
    (lambda p: None, 'cannot open'),
], ids=['truncated', 'protobuf_schema', 'unknown_type', 'no_threat_topic', 'not_mcap',
        'missing'])
def test_bad_bag_exits_2_with_one_line(tmp_path, make, needle):
    bag = tmp_path / 'bad.mcap'
    make(bag)
    p = cli('replay', bag)
    one_line_error(p, needle)
    assert str(bag) in p.stderr


def test_bad_options_exit_2(tmp_path):
    one_line_error(cli('replay', BAGS / 'ground.mcap', '--tolerance', '-1'), 'tolerance')
    one_line_error(cli('replay', BAGS / 'ground.mcap', '--w', '2'), 'w: must satisfy')
    one_line_error(cli('replay', BAGS / 'ground.mcap', '--live', '--rate', '0'), 'rate')


def test_tolerant_replay_of_a_cut_file_uses_its_complete_chunks(tmp_path):
    bag, full_bag = tmp_path / 'cut.mcap', BAGS / 'moving_uniform20.mcap'
    with open(full_bag, 'rb') as f:
        chunk = make_reader(f).get_summary().chunk_indexes[-2]
    # Cut inside the last but one chunk, as a kill while writing it would.
    bag.write_bytes(full_bag.read_bytes()[:chunk.chunk_start_offset + chunk.chunk_length // 2])
    with pytest.raises(RecordingError, match='truncated'):
        load_bag(bag)
    cut = load_bag(bag, tolerant=True)
    full = load_bag(full_bag)
    assert 0 < len(cut.plans) < len(full.plans)
    assert replay_bag(cut).ok


# ----------------------------------------------------------------- live node


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'test_replay_client')
    yield c
    c.close()


def start_node(client, ns, params, log):
    proc = start_process(planner_command(ns, params), DOMAIN, log)
    client.subscribe(f'{ns}/plan_info', DiagnosticArray)
    client.subscribe(f'{ns}/path', PathMsg)
    pubs = {'threats': client.publisher(f'{ns}/threats', PointCloud2),
            'start': client.publisher(f'{ns}/start', PoseStamped, VOLATILE),
            'goal_pose': client.publisher(f'{ns}/goal_pose', PoseStamped, VOLATILE)}
    for pub in pubs.values():
        client.wait_matched(pub, timeout=30.0)
    return proc, pubs


def wait_info(client, ns, pred, timeout=60.0):
    return info(client.wait_for(f'{ns}/plan_info', lambda m: pred(info(m)), timeout))


def test_live_node_recording_replays_to_the_same_plans(client, tmp_path):
    ns, out = '/rec_replay', tmp_path / 'run.mcap'
    box = SCENARIO.box
    proc, pubs = start_node(client, ns, {'method': 'paper', 'record': str(out),
                                         'bounds': box.lo.tolist() + box.hi.tolist()},
                            tmp_path / 'node.log')
    try:
        pubs['start'].publish(pose([5.0, 5.0, 40.0], stamp=Time(sec=1)))
        pubs['goal_pose'].publish(pose([95.0, 90.0, 60.0], stamp=Time(sec=2)))
        pubs['threats'].publish(cloud(SCENARIO.threats.positions,
                                      SCENARIO.threats.intensities, stamp=Time(sec=3)))
        wait_info(client, ns, lambda i: i['input_seq'] == '3' and i['level'] != 'ERROR')
        assert client.set_parameters(f'{ns}/threat_planner', {'w': 0.7})[0].successful
        wait_info(client, ns, lambda i: i['input_source'] == 'parameters')
        bad = SCENARIO.threats.positions.copy()
        bad[2, 1] = math.nan
        pubs['threats'].publish(cloud(bad, SCENARIO.threats.intensities, stamp=Time(sec=4)))
        wait_info(client, ns, lambda i: i['level'] == 'ERROR')
        pubs['threats'].publish(cloud(SCENARIO.threats.positions + 1.5,
                                      SCENARIO.threats.intensities, stamp=Time(sec=5)))
        wait_info(client, ns, lambda i: i['input_stamp_ns'] == str(5 * 10**9))
    finally:
        code = stop_process(proc)
    assert code == 0, (tmp_path / 'node.log').read_text()

    report = tmp_path / 'replay.md'
    p = cli('replay', out, '--report', report)
    assert p.returncode == 0, p.stdout + p.stderr
    text = report.read_text()
    assert '| rejected | rejected |' in text and '| parameters |' in text
    assert 'all within tolerance' in text


def test_live_replay_drives_a_node_to_the_recorded_plans(client, tmp_path):
    ns, out = '/live_replay', tmp_path / 'live.mcap'
    # Default settings ('best'): the replay sets the bag's parameters ('paper').
    proc = start_process(planner_command(ns, {'record': str(out)}), DOMAIN,
                         tmp_path / 'node.log')
    try:
        bag = BAGS / 'moving_uniform20.mcap'
        p = cli('replay', bag, '--live', '--rate', '4', '--namespace', ns,
                env=ros_env(DOMAIN), timeout=120)
        assert p.returncode == 0, p.stdout + p.stderr
        messages = sum(i.kind != 'parameters' for i in load_bag(bag).inputs)
        assert f'published {messages} messages' in p.stdout
        assert f'{ns}/threat_planner' in p.stdout
    finally:
        code = stop_process(proc)
    assert code == 0, (tmp_path / 'node.log').read_text()

    live = load_bag(out)
    assert live.namespace == ns and len(live.plans) >= 1
    assert {p.values['method'] for p in live.plans} == {'paper'}
    p = cli('replay', out)
    assert p.returncode == 0, p.stdout + p.stderr
    # The node ended in the bag's last input state: its last plan is what re-planning the
    # bag's last state gives (compared with today's planner, not the recorded plan, so
    # that this test does not depend on the bag being up to date).
    original = load_bag(bag)
    assert live.plans[-1].stamp_ns == original.plans[-1].stamp_ns
    expected = replay_bag(original).rows[-1]
    assert float(live.plans[-1].values['J']) == pytest.approx(expected.j_replayed, rel=1e-12)


def test_live_replay_counts_a_plan_that_took_every_input_as_the_answer():
    from threat_planner.ros.recording.live import _answers_everything
    ours = {('/n/threats', 5), ('/n/terrain', 4)}

    def answer(seq, received, source='/n/terrain', stamp=4):
        return {'input_seq': str(seq), 'inputs_received': str(received),
                'input_source': source, 'input_stamp_ns': str(stamp)}
    # The terrain reached the node after the last input (the threats) and the plan named
    # it: every input of ours is in that plan.
    assert _answers_everything(answer(7, 7), True, 7, ours)
    assert _answers_everything(answer(8, 8, 'parameters', 0), True, 7, ours)
    # Not yet: an input arrived after the plan's, or ours are not all counted, or the
    # plan came before the last publish, or it names somebody else's input.
    assert not _answers_everything(answer(6, 7), True, 7, ours)
    assert not _answers_everything(answer(6, 6), True, 7, ours)
    assert not _answers_everything(answer(7, 7), False, 7, ours)
    assert not _answers_everything(answer(7, 7, '/other/threats', 5), True, 7, ours)
    assert not _answers_everything(dict(answer(7, 7), input_seq='x'), True, 7, ours)


def test_live_replay_without_a_node_exits_2():
    p = cli('replay', BAGS / 'ground.mcap', '--live', '--namespace', '/nobody',
            '--timeout', '2', env=ros_env(DOMAIN))
    one_line_error(p, 'no subscriber on /nobody/threats')


def test_sigkill_mid_recording_leaves_a_readable_file(client, tmp_path):
    ns, out = '/killed', tmp_path / 'killed.mcap'
    proc, pubs = start_node(client, ns, {'method': 'paper', 'record': str(out)},
                            tmp_path / 'node.log')
    try:
        for sec in (1, 2, 3):
            pubs['threats'].publish(cloud(SCENARIO.threats.positions + 0.5 * sec,
                                          SCENARIO.threats.intensities, stamp=Time(sec=sec)))
            wait_info(client, ns, lambda i: i['input_stamp_ns'] == str(sec * 10**9))
        time.sleep(1.5)  # > the recorder's 1 s flush interval
        proc.send_signal(signal.SIGKILL)
        assert proc.wait(10) == -signal.SIGKILL
    finally:
        stop_process(proc)

    with pytest.raises(RecordingError, match='truncated'):
        list(read_messages(out))
    got = list(read_messages(out, tolerant=True))
    topics = [m.topic for m in got]
    assert topics[0] == '/parameter_events'
    assert topics.count(f'{ns}/threats') == 3 and topics.count(f'{ns}/plan_info') == 3
    one_line_error(cli('replay', out), 'truncated MCAP file')
    p = cli('replay', out, '--tolerant')
    assert p.returncode == 0, p.stdout + p.stderr
    assert '3 plans replayed' in p.stdout
