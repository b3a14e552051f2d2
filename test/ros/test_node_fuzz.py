"""Fuzz test of the planner node: hundreds of malformed, hostile and good inputs in a row.

One planner node process (method 'paper', recording on) gets ``N_MESSAGES`` inputs drawn
with a fixed seed: good threat pictures in random but valid PointCloud2 layouts (field
order, FLOAT32/FLOAT64, padding fields and bytes, row padding, big endian, several rows),
good PoseArrays, starts and goals, and bad ones (truncated or extended data, wrong
point_step or row_step, missing, duplicated, overlapping, multi-count or integer fields,
huge offsets and sizes, a 10^6-point cloud, other frame ids, NaN/inf positions and poses,
zero or negative intensities, too many threats, start or goal outside the box or on a
threat), plus random field layouts, byte-flipped clouds and extreme values (threats 1e30 m
away, intensities 1e-45 or 3.4e38) whose fate an oracle decides.

The oracle is the node's own validation run in this process on the same state (the node
is a process boundary away, so this checks transport and the node's bookkeeping), and for
the intended-good clouds the decoded values are also checked against an independent
encoder. Each input is sent only after the previous one is answered, so no update is
coalesced and every one must get its own ``plan_info``:

* a good input: status OK or WARN, ``input_seq`` one more than the last, a ``path`` with
  its stamp that starts at the current start and ends at the current goal (and, for the
  intended-good ones, equals the library's plan for the same decoded threats);
* a bad input: status ERROR with the reason, the node still alive;
* every 25 inputs and at the end: the process is alive and its parameter service answers.

An accepted 'either' picture may still fail to plan (a threat 1e20 m or more outside the
box makes scipy's Qhull fail in the partition): that is an ERROR answer too, counted
apart as ``accepted_but_not_planned``. At the end the recording must hold every input,
by stamp. Set ``THREAT_PLANNER_RESULTS``
to a folder to also write the counts there as ``reliability_fuzz.json``; ``FUZZ_SEED``
and ``FUZZ_MESSAGES`` draw other or longer sequences.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import json
import os
from pathlib import Path
import signal
import threading
import time
from typing import Optional

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import PointCloud2

from fuzz_cases import (BOX, Case, draw_cases, Model, N_MESSAGES, oracle, PARAMS, SEED,
                        SETTINGS, stamp_for)
from fuzz_messages import FRAME, MAX_THREATS
from node_harness import (domain_id, info, planner_command, RosClient, start_process,
                          stop_process, VOLATILE)
from threat_planner.bag import read_messages
from threat_planner.core.planner import plan
from threat_planner.ros.conversions import path_from_msg, stamp_to_ns, threats_from_pointcloud2

DOMAIN = domain_id(16)
NS = '/fuzz'
#: Longest wait for one answer [s]; the 10^6-point cloud is the slow one (16 MB).
ANSWER_TIMEOUT_S = 30.0


# ---------------------------------------------------------------------- the test


@dataclass
class Tally:
    """Counts of the run."""

    tried: int = 0
    good: int = 0
    bad: int = 0
    either_planned: int = 0
    either_refused: int = 0
    crashes: int = 0
    good_without_plan: list = field(default_factory=list)
    bad_not_reported: list = field(default_factory=list)
    wrong_answers: list = field(default_factory=list)
    accepted_but_not_planned: list = field(default_factory=list)
    unclean_rejections: list = field(default_factory=list)
    parameter_checks: int = 0
    parameter_failures: int = 0
    labels: dict = field(default_factory=dict)
    seconds: float = 0.0


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'fuzz_client')
    yield c
    c.close()


def parameter_ok(params: AsyncParameterClient, timeout: float = 5.0) -> bool:
    """Whether the node answers a parameter get within `timeout`."""
    done = threading.Event()
    future = params.get_parameters(['max_threats'])
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        return False
    values = future.result().values
    return len(values) == 1 and values[0].integer_value == MAX_THREATS


def check_plan(client, case: Case, model: Model, values: dict, stamp: Time,
               paths_before: int) -> Optional[str]:
    """What is wrong with the plan answering `case` (`model` after it), or None."""
    if values['level'] not in ('OK', 'WARN'):
        return f'level {values["level"]}'
    t0 = int(values['t0_ns'])   # the paths carry the plan's t0, not the input's stamp
    path = client.wait_for(f'{NS}/path', lambda m: stamp_to_ns(m.header.stamp) == t0, 10.0,
                           after=paths_before)
    points = path_from_msg(path)
    if not (np.allclose(points[0], model.start, atol=1e-6)
            and np.allclose(points[-1], model.goal, atol=1e-6)):
        return f'path {points[0].tolist()}..{points[-1].tolist()} does not join start and goal'
    if int(values['threats']) != len(model.threats):
        return f'{values["threats"]} threats planned, {len(model.threats)} sent'
    if case.intent == 'good':
        expected = plan(model.threats, model.start, model.goal, BOX, SETTINGS.config)
        if not np.allclose(points, expected.path, rtol=0.0, atol=1e-6):
            return 'path differs from the library plan of the same threats'
    return None


def test_fuzzed_inputs_are_each_answered(client, tmp_path):
    record = tmp_path / 'fuzz.mcap'
    log = tmp_path / 'node.log'
    proc = start_process(planner_command(NS, {**PARAMS, 'record': str(record)}), DOMAIN, log)
    for name, msg_type in (('plan_info', DiagnosticArray), ('path', PathMsg)):
        client.subscribe(f'{NS}/{name}', msg_type)
    pubs = {'threats': client.publisher(f'{NS}/threats', PointCloud2),
            'threat_poses': client.publisher(f'{NS}/threat_poses', PoseArray),
            'start': client.publisher(f'{NS}/start', PoseStamped, VOLATILE),
            'goal_pose': client.publisher(f'{NS}/goal_pose', PoseStamped, VOLATILE)}
    for pub in pubs.values():
        client.wait_matched(pub, timeout=30.0)
    params = AsyncParameterClient(client.node, f'{NS}/threat_planner')
    assert params.wait_for_services(timeout_sec=30.0)

    model = Model(SETTINGS.start, SETTINGS.goal)
    stamp_rng = np.random.default_rng(SEED + 1)
    tally = Tally()
    sent_stamps = []
    t0 = time.monotonic()
    try:
        for k, make in enumerate(draw_cases(N_MESSAGES, SEED)):
            case = make(model)
            if model.exotic and case.topic in ('start', 'goal_pose'):
                case.intent = 'either'
            oracle(case, model)
            if case.intent == 'good':
                assert case.accept, (case.label, case.reason)
                if case.expected is not None and case.topic == 'threats':
                    pos, inten = threats_from_pointcloud2(case.msg, FRAME)
                    np.testing.assert_array_equal(pos, case.expected[0])
                    np.testing.assert_array_equal(inten, case.expected[1])
            elif case.intent == 'bad':
                assert not case.accept, case.label
            if case.reason.startswith('cannot read:'):
                tally.unclean_rejections.append((case.label, case.reason))
            stamp = stamp_for(k, stamp_rng)
            case.msg.header.stamp = stamp
            stamp_ns = stamp_to_ns(stamp)
            sent_stamps.append((case.topic, stamp_ns))
            tally.tried += 1
            tally.labels[case.label] = tally.labels.get(case.label, 0) + 1
            infos_before = client.count(f'{NS}/plan_info')
            paths_before = client.count(f'{NS}/path')
            pubs[case.topic].publish(case.msg)
            try:
                answer = client.wait_for(
                    f'{NS}/plan_info', lambda m: int(info(m)['input_stamp_ns']) == stamp_ns
                    and int(info(m)['input_seq']) == k + 1, ANSWER_TIMEOUT_S,
                    after=infos_before)
            except TimeoutError:
                answer = None
            if proc.poll() is not None:
                tally.crashes += 1
                break
            values = info(answer) if answer is not None else None
            if case.accept:
                tally.good += case.intent == 'good'
                planned_model = case.after
                model = case.after
                if values is None or values['level'] == 'ERROR':
                    what = (case.label, k, values and values['message'][:200])
                    if case.intent == 'good':
                        tally.good_without_plan.append(what)
                    else:
                        tally.accepted_but_not_planned.append(what)
                    continue
                problem = check_plan(client, case, planned_model, values, stamp,
                                     paths_before)
                if problem:
                    tally.wrong_answers.append((case.label, k, problem))
                tally.either_planned += case.intent == 'either'
            else:
                tally.bad += case.intent == 'bad'
                tally.either_refused += case.intent == 'either'
                if values is None or values['level'] != 'ERROR' or not values.get('error') \
                        or f'{NS}/{case.topic}' not in values['message']:
                    tally.bad_not_reported.append((case.label, k, values))
            if k % 25 == 0:
                tally.parameter_checks += 1
                tally.parameter_failures += not parameter_ok(params)
        tally.parameter_checks += 1
        tally.parameter_failures += not parameter_ok(params)
        tally.seconds = time.monotonic() - t0
    finally:
        code = stop_process(proc, signal.SIGINT)
    tally.crashes += code != 0

    recorded = [(m.topic, stamp_to_ns(m.msg.header.stamp)) for m in read_messages(record)
                if m.topic.rsplit('/', 1)[-1] in pubs]
    summary = {**tally.__dict__, 'exit_code': code, 'recorded_inputs': len(recorded),
               'inputs_missing_from_recording': len(
                   set((f'{NS}/{t}', s) for t, s in sent_stamps) - set(recorded))}
    print(json.dumps(summary, indent=1, default=str))
    out = os.environ.get('THREAT_PLANNER_RESULTS')
    if out:
        Path(out, 'reliability_fuzz.json').write_text(
            json.dumps(summary, indent=2, default=str, sort_keys=True) + '\n')

    assert tally.tried == N_MESSAGES, log.read_text()
    assert tally.crashes == 0 and code == 0, log.read_text()[-5000:]
    assert tally.good_without_plan == []
    assert tally.bad_not_reported == []
    assert tally.wrong_answers == []
    assert tally.parameter_failures == 0
    assert tally.unclean_rejections == []
    assert summary['inputs_missing_from_recording'] == 0
    assert tally.good > 50 and tally.bad > 100
