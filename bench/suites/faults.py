"""Faults: kill -9 the planner node while it plans and while it records, and SIGINT it.

Three experiments, each on a planner node process of its own (method 'paper'):

``kill_while_planning``
    A latched publisher sends a picture that takes seconds to plan; once the node has had
    it for ``--wait`` s without answering, the node gets SIGKILL. It is restarted with the
    same parameters: it must plan the latched picture (input #1 of the new process) and
    then the next picture sent. The killed run's recording (a bag folder) is read with
    the tolerant reader: it must hold the picture.
``kill_while_recording``
    The node records a flood of pictures (``--rate`` Hz, 20 threats) and gets SIGKILL
    in the middle of it (3 s in; each further run 0.37 s later). The tolerant reader
    must read the killed bag without error; the pictures in it must be in the order sent,
    without duplicates, and include every picture sent more than ``flush_interval_s``
    (1 s) + 1 s before the kill (pictures DDS dropped before the node took them, which
    a flood can cause, are reported as gaps). The restarted node plans the last picture
    (latched).
``sigint_during_long_plan``
    The node, recording to a ``.mcap`` file, gets a 10000-threat picture
    (``/work/shared/scenarios/scale10000.yaml`` if present, else random) and SIGINT while
    it plans. It must exit, with code 0, within 1 s of the signal, and the recording must
    be finished (strict reading, which needs the summary, succeeds).

Usage::

    .venv/bin/python -m bench faults                 # all three, writes the results
    .venv/bin/python -m bench faults --repeats 5 --out ''

``test/ros/test_node_faults.py`` runs the same functions at CI size.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Optional

import numpy as np

from bench.toolkit.cases import random_scenario
from bench.toolkit.node import jitter, NodeProcess, RosClient, ros_session, scenario_params
from bench.toolkit.repo import DATA, SHARED
from bench.toolkit.report import write_results
from bench.toolkit.timing import load_average, stats
from threat_planner.bag import read_messages
from threat_planner.core.inputs.scenario import load_scenario, Scenario
from threat_planner.errors import RecordingError
from threat_planner.ros.conversions import stamp_to_ns

SCALE10000 = SHARED / 'scale10000.yaml'
FLUSH_INTERVAL_S = 1.0
SIGINT_LIMIT_S = 1.0


def _node(client: RosClient, work: Path, ns: str, scenario: Scenario, record: str,
          **params) -> NodeProcess:
    """Return a node in `ns` recording to ``work/<ns><record>``, its logs in `work`."""
    stem = ns.strip('/')
    return NodeProcess(client, ns, scenario_params(scenario, **params,
                                                   record=str(work / f'{stem}{record}')),
                       work / f'{stem}.log')


def _killed(read: dict) -> dict:
    """Return the fields of the killed bag's reading that every kill reports."""
    return {'killed_bag_error': read['error'], 'killed_bag_messages': read['messages'],
            'killed_bag_strict_read': read['strict']}


def _only_bag(folder: Path, known: set) -> Path:
    new = [d for d in folder.iterdir() if d.is_dir() and d not in known]
    assert len(new) == 1, new
    return new[0]


def _read_tolerant(bag: Path, topic: str) -> dict:
    """Read a killed bag tolerantly; the stamps of `topic` and a strict-read check."""
    stamps, count, error = [], 0, None
    try:
        for m in read_messages(bag, tolerant=True):
            count += 1
            if m.topic == topic:
                stamps.append(stamp_to_ns(m.msg.header.stamp))
    except RecordingError as exc:
        error = str(exc)
    try:
        list(read_messages(bag))
        strict = 'finished'
    except RecordingError as exc:
        strict = 'truncated' if 'truncated' in str(exc) else f'unreadable: {exc}'
    return {'stamps': stamps, 'messages': count, 'error': error, 'strict': strict}


def kill_while_planning(client: RosClient, work: Path, scenario: Scenario,
                        wait_s: float = 1.5, method: str = 'paper',
                        replace_while_down: bool = False, ns: str = '/fault_plan') -> dict:
    """SIGKILL the node while it plans, restart it, check the replan and the bag.

    Parameters
    ----------
    client, work : RosClient, Path
        The client in the node's domain; the folder of the logs and bags.
    scenario : Scenario
        A picture that takes longer than `wait_s` to plan.
    wait_s : float
        Time from the publish to the kill [s].
    method : str
        Planner method.
    replace_while_down : bool
        Publish a small picture (the first 20 threats) while the node is down, so that
        the latched picture the restarted node gets is a quick one; else it replans the
        big picture it was killed on.
    ns : str
        Namespace of the node.

    Returns
    -------
    dict
        What happened, with ``ok`` True if every check passed.
    """
    node = _node(client, work, ns, scenario, '_bags', method=method)
    bags = work / f'{ns.strip("/")}_bags'
    positions, intensities = scenario.threats.positions, scenario.threats.intensities
    stamp_a, stamp_b, stamp_small = 7_000_000_001, 7_000_000_002, 7_000_000_003
    try:
        after = node.start()
        t_pub = node.publish(positions, intensities, stamp_a)
        time.sleep(wait_s)
        was_planning = not node.answered(stamp_a, after) and node.proc.poll() is None
        first_bag = _only_bag(bags, set())
        t_kill = node.kill()
        killed = _read_tolerant(first_bag, f'{ns}/threats')

        known = {first_bag}
        latched_stamp = stamp_a
        if replace_while_down:
            latched_stamp = stamp_small
            node.publish(positions[:20], intensities[:20], stamp_small)
        t_restart = time.monotonic()
        after = node.start()
        latched = node.wait_answer(latched_stamp, after)
        replan_latched_s = time.monotonic() - t_restart
        after = client.count(node.info_topic)
        node.publish(positions[:20], intensities[:20], stamp_b)
        nxt = node.wait_answer(stamp_b, after)
        second_bag = _only_bag(bags, known)
    finally:
        code = node.stop()
    result = {
        'threats': len(positions), 'method': method, 'kill_after_s': t_kill - t_pub,
        'was_planning_when_killed': was_planning, **_killed(killed),
        'killed_bag_holds_input': killed['stamps'] == [stamp_a],
        'latched_input': 'small, sent while down' if replace_while_down
        else 'the one killed on',
        'restart_plans_latched_input': latched['level'] != 'ERROR'
        and latched['input_seq'] == '1',
        'restart_to_latched_plan_s': replan_latched_s,
        'restart_plans_next_input': nxt['level'] != 'ERROR' and nxt['input_seq'] == '2',
        'second_bag': second_bag.name, 'exit_code_after_restart': code,
    }
    result['ok'] = (was_planning and killed['error'] is None and result['killed_bag_holds_input']
                    and result['restart_plans_latched_input']
                    and result['restart_plans_next_input'] and code == 0)
    return result


def kill_while_recording(client: RosClient, work: Path, scenario: Scenario,
                         rate: float = 50.0, kill_after_s: float = 3.0, seed: int = 0,
                         ns: str = '/fault_rec') -> dict:
    """SIGKILL the node in the middle of a recorded flood; check the bag and a restart.

    `client`, `work` and `ns` as :func:`kill_while_planning` takes them; the flood is
    `scenario`'s threats, jittered (seed `seed`), at `rate` [Hz], the kill `kill_after_s`
    [s] after its first picture. Returns what happened, ``ok`` True if every check passed.
    """
    node = _node(client, work, ns, scenario, '_bags', method='paper', n_points=20)
    bags = work / f'{ns.strip("/")}_bags'
    rng = np.random.default_rng(seed)
    positions, intensities = scenario.threats.positions, scenario.threats.intensities
    sent: list[tuple[int, float]] = []
    try:
        after = node.start()
        # One answered picture first: both ends matched before the counted flood.
        node.publish(positions, intensities, 1)
        node.wait_answer(1, after)
        t0 = time.monotonic()
        k = 0
        while True:
            delay = t0 + k / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            if time.monotonic() - t0 >= kill_after_s:
                break
            stamp = 8_000_000_000 + k
            sent.append((stamp, node.publish(jitter(positions, rng), intensities, stamp)))
            k += 1
        first_bag = _only_bag(bags, set())
        t_kill = node.kill()
        killed = _read_tolerant(first_bag, f'{ns}/threats')
        after = node.start()
        latched = node.wait_answer(sent[-1][0], after)
    finally:
        code = node.stop()
    got = [s for s in killed['stamps'] if s != 1]
    stamps = [s for s, _ in sent]
    sent_at = dict(sent)
    must_have = [s for s, t in sent if t < t_kill - FLUSH_INTERVAL_S - 1.0]
    # Pictures the node never took from its subscription (DDS dropped them in a flood)
    # show as gaps: they were never inputs, so the recording cannot hold them.
    gaps = sorted(set(stamps[:stamps.index(got[-1]) + 1]) - set(got)) if got else []
    result = {
        'threats': len(positions), 'rate_hz': rate, 'inputs_sent': len(sent),
        **_killed(killed), 'inputs_in_killed_bag': len(got),
        'in_order_no_duplicates': got == sorted(set(got)) and set(got) <= set(stamps),
        'not_received_gaps': len(gaps),
        'bag_is_prefix_of_sent': got == stamps[:len(got)],
        'bag_holds_all_older_than_flush': set(must_have) <= set(got),
        'inputs_after_last_in_bag': len(sent) - (stamps.index(got[-1]) + 1 if got else 0),
        'unrecorded_window_s': t_kill - sent_at[got[-1]] if got else None,
        'restart_plans_latched_last_input': latched['level'] != 'ERROR'
        and latched['input_seq'] == '1',
        'exit_code_after_restart': code,
    }
    result['ok'] = (killed['error'] is None and result['in_order_no_duplicates']
                    and result['bag_holds_all_older_than_flush']
                    and result['restart_plans_latched_last_input'] and code == 0)
    return result


def sigint_during_long_plan(client: RosClient, work: Path, scenario: Scenario,
                            wait_s: float = 1.5, ns: str = '/fault_sigint') -> dict:
    """SIGINT the node while it plans a big picture; time the exit, check the recording.

    `client`, `work` and `ns` as :func:`kill_while_planning` takes them; `scenario` takes
    much longer than `wait_s` [s], the time from the publish to the signal, to plan.
    Returns the exit time [s], exit code and recording check, ``ok`` True if all passed.
    """
    node = _node(client, work, ns, scenario, '.mcap', method='paper')
    target = work / f'{ns.strip("/")}.mcap'
    stamp = 9_000_000_001
    try:
        after = node.start()
        node.publish(scenario.threats.positions, scenario.threats.intensities, stamp)
        time.sleep(wait_s)
        was_planning = not node.answered(stamp, after) and node.proc.poll() is None
        t_sig = time.monotonic()
        node.proc.send_signal(signal.SIGINT)
        try:
            code = node.proc.wait(30.0)
        except subprocess.TimeoutExpired:
            code = None
        exit_s = time.monotonic() - t_sig
    finally:
        node.stop()
    log = node.log_path.with_name(f'{node.log_path.stem}_0.log').read_text(errors='replace')
    try:
        recorded = [m for m in read_messages(target)]  # strict: needs the summary
        finished, error = True, None
    except RecordingError as exc:
        recorded, finished, error = [], False, str(exc)
    inputs = [m for m in recorded if m.topic == f'{ns}/threats']
    result = {
        'threats': len(scenario.threats), 'was_planning': was_planning,
        'exit_s': exit_s, 'exit_code': code,
        'plan_abandoned_logged': 'still running' in log,
        'recording_finished': finished, 'recording_error': error,
        'recording_holds_input': len(inputs) == 1
        and stamp_to_ns(inputs[0].msg.header.stamp) == stamp,
    }
    result['ok'] = (was_planning and code == 0 and exit_s <= SIGINT_LIMIT_S and finished
                    and result['recording_holds_input'])
    return result


def _of(runs: list[dict], test) -> str:
    """Return ``k/n``: how many of the runs pass `test`, a result key or a function of one."""
    hits = sum(bool(test(x) if callable(test) else x[test]) for x in runs)
    return f'{hits}/{len(runs)}'


def markdown(results: dict) -> str:
    """Return the Markdown summary of the experiments."""
    lines = ['### Faults', '']
    if 'kill_while_planning' in results:
        runs = results['kill_while_planning']
        r = runs[0]
        held = _of(runs, lambda x: x['killed_bag_holds_input'] and not x['killed_bag_error'])
        lines += [
            f"**kill -9 while planning** ({r['threats']} threats, {r['method']}, killed "
            f"{r['kill_after_s']:.1f} s after the picture, {len(runs)} runs): "
            f"{_of(runs, 'ok')} passed; killed bag read tolerantly without error and holding "
            f"the picture in {held}; restarted node planned the latched picture (input #1) "
            f"in {_of(runs, 'restart_plans_latched_input')} and the next picture in "
            f"{_of(runs, 'restart_plans_next_input')}; restart -> latched plan median "
            f"{stats([x['restart_to_latched_plan_s'] for x in runs])['median']:.1f} s.", '']
    if 'kill_while_recording' in results:
        runs = results['kill_while_recording']
        r = runs[0]
        lost = stats([x['inputs_after_last_in_bag'] for x in runs])
        window = stats([x['unrecorded_window_s'] for x in runs])
        strict = ', '.join(sorted(set(x['killed_bag_strict_read'] for x in runs)))
        lines += [
            f"**kill -9 while recording** ({r['threats']} threats at {r['rate_hz']:g} Hz, "
            f"{len(runs)} runs): {_of(runs, 'ok')} passed; tolerant read without error in "
            f"{_of(runs, lambda x: x['killed_bag_error'] is None)} (strict read: {strict}); "
            f"inputs in order without duplicates in {_of(runs, 'in_order_no_duplicates')}, "
            f"exactly the first pictures sent in {_of(runs, 'bag_is_prefix_of_sent')} "
            "(pictures never received by the node: "
            f"{sum(x['not_received_gaps'] for x in runs)}); every picture older than flush "
            f"interval + 1 s present in {_of(runs, 'bag_holds_all_older_than_flush')}; "
            f"pictures sent after the last one in the bag: median {lost['median']:.0f}, "
            f"max {lost['max']:.0f} (the last {window['median']:.2f} s, max "
            f"{window['max']:.2f} s before the kill); restarted node planned the latched "
            f"last picture in {_of(runs, 'restart_plans_latched_last_input')}.", '']
    if 'sigint_during_long_plan' in results:
        runs = results['sigint_during_long_plan']
        exit_s = stats([x['exit_s'] for x in runs])
        lines += [
            f"**SIGINT during a long plan** ({runs[0]['threats']} threats, {len(runs)} runs):"
            f" {_of(runs, 'ok')} passed; exit after SIGINT median "
            f"{1e3 * exit_s['median']:.0f} ms, max {1e3 * exit_s['max']:.0f} ms (limit "
            f"{1e3 * SIGINT_LIMIT_S:.0f} ms), exit codes "
            f"{sorted(set(x['exit_code'] for x in runs))}; recording finished (strict read) "
            f"in {_of(runs, 'recording_finished')}.", '']
    return '\n'.join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    """Run the experiments and print (and write) the results."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--rate', type=float, default=50.0,
                        help='pictures per second of the recorded flood [Hz]')
    parser.add_argument('--recorded', type=Path,
                        default=DATA / 'uniform20_0.yaml',
                        help='scenario of the recorded flood')
    parser.add_argument('--only', choices=['kill_while_planning', 'kill_while_recording',
                                           'sigint_during_long_plan'], action='append')
    parser.add_argument('--out', default='reliability_faults',
                        help="results stem under bench/results ('' = do not write)")
    args = parser.parse_args(argv)

    big = load_scenario(SCALE10000) if SCALE10000.exists() else random_scenario(10000)
    slow = random_scenario(2000)  # 'paper' takes ~20 s on it
    flood_scenario = load_scenario(args.recorded)
    results: dict[str, list] = {}
    todo = args.only or ['kill_while_planning', 'kill_while_recording',
                         'sigint_during_long_plan']
    with ros_session(101, 1, 'faults_bench', 'faults_') as (client, tmp):
        for k in range(args.repeats):
            work = tmp / f'run{k}'
            work.mkdir()
            if 'kill_while_planning' in todo:
                results.setdefault('kill_while_planning', []).append(
                    kill_while_planning(client, work, slow, ns=f'/fault_plan{k}'))
            if 'kill_while_recording' in todo:
                results.setdefault('kill_while_recording', []).append(
                    kill_while_recording(client, work, flood_scenario, args.rate,
                                         kill_after_s=3.0 + 0.37 * k, seed=k,
                                         ns=f'/fault_rec{k}'))
            if 'sigint_during_long_plan' in todo:
                results.setdefault('sigint_during_long_plan', []).append(
                    sigint_during_long_plan(client, work, big, ns=f'/fault_sigint{k}'))
            print(f'run {k}: ' + ', '.join(f'{name} ok={runs[-1]["ok"]}'
                                           for name, runs in results.items()),
                  file=sys.stderr, flush=True)
    text = markdown(results) + f'\nHost load average (1 min) at the end: {load_average():.1f}.\n'
    print(text)
    if args.out:
        write_results(args.out, results, text)
    return 0 if all(r['ok'] for runs in results.values() for r in runs) else 1
