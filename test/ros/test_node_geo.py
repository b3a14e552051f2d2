"""GNSS fixes in: NavSatFix on start_fix and goal_fix, converted with parameter datum.

The input path is checked in-process (accept(), as node and replay share it); one node
process, started from config/planner.yaml (datum: [], which a params file cannot type),
shows the topics end to end: a fix is refused until datum is set at run time, then plans
start and end at pymap3d's ENU of the fixes.
"""

import math

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pymap3d
import pytest
from sensor_msgs.msg import NavSatFix, NavSatStatus, PointCloud2

from node_harness import (cloud, domain_id, info, LATCHED_LOG, planner_command, RosClient,
                          start_process, stop_process, VOLATILE)
from threat_planner.errors import InputError
from threat_planner.ros.conversions import navsatfix_from_geodetic, path_from_msg, stamp_to_ns
from threat_planner.ros.inputs import accept, InputState
from threat_planner.ros.parameters import PARAMETER_DEFAULTS

DATUM = [47.3977, 8.5456, 488.0]
DOMAIN = domain_id(150)
NS = '/geo'


def geodetic(enu):
    lat, lon, h = pymap3d.enu2geodetic(*enu, *DATUM)
    return float(lat), float(lon), float(h)


def state(datum=DATUM):
    return InputState.from_parameters({**PARAMETER_DEFAULTS, 'datum': datum})


def test_a_fix_becomes_the_start_in_enu():
    s = accept(state(), 'start_fix', navsatfix_from_geodetic(*geodetic([12.0, 34.0, 56.0])))
    np.testing.assert_allclose(s.start, [12.0, 34.0, 56.0], atol=1e-6)
    s = accept(s, 'goal_fix', navsatfix_from_geodetic(*geodetic([90.0, 80.0, 70.0])))
    np.testing.assert_allclose(s.goal, [90.0, 80.0, 70.0], atol=1e-6)


def refusal(msg, datum=DATUM, kind='start_fix'):
    with pytest.raises(InputError) as exc:
        accept(state(datum), kind, msg)
    return str(exc.value)


def test_no_fix_nan_out_of_range_and_no_datum_are_refused_with_the_reason():
    msg = navsatfix_from_geodetic(*geodetic([10.0, 10.0, 50.0]))
    msg.status.status = NavSatStatus.STATUS_NO_FIX
    assert 'NO_FIX' in refusal(msg)
    for field in ('latitude', 'longitude', 'altitude'):
        msg = navsatfix_from_geodetic(*geodetic([10.0, 10.0, 50.0]))
        setattr(msg, field, math.nan)
        assert f'{field} is nan' in refusal(msg, kind='goal_fix')
    assert 'latitude 91 outside [-90, 90]' in refusal(navsatfix_from_geodetic(91.0, 8.0, 0.0))
    assert 'datum is empty' in refusal(navsatfix_from_geodetic(*geodetic([1, 1, 1])), [])
    # A fix outside the bounds is refused as a start pose would be.
    assert 'start' in refusal(navsatfix_from_geodetic(*geodetic([500.0, 10.0, 50.0])))


def test_a_bad_datum_parameter_is_refused():
    with pytest.raises(InputError, match='datum: latitude 100 outside'):
        state([100.0, 8.0, 0.0])
    with pytest.raises(InputError, match='datum'):
        state([47.0, 8.0])


@pytest.fixture
def node(tmp_path):
    client = RosClient(DOMAIN, 'geo_client')
    proc = start_process(planner_command(NS), DOMAIN, tmp_path / 'node.log')
    try:
        yield client, proc, tmp_path / 'node.log'
    finally:
        stop_process(proc)
        client.close()


def test_node_takes_fixes_once_datum_is_set(node):
    client, proc, log = node
    client.subscribe(f'{NS}/plan_info', DiagnosticArray, LATCHED_LOG)
    client.subscribe(f'{NS}/path', PathMsg)
    threats = client.publisher(f'{NS}/threats', PointCloud2)
    fixes = {k: client.publisher(f'{NS}/{k}', NavSatFix, VOLATILE)
             for k in ('start_fix', 'goal_fix')}
    for pub in (threats, *fixes.values()):
        client.wait_matched(pub, timeout=30.0)

    def answer(sec):
        ns = str(sec * 1_000_000_000)
        return info(client.wait_for(f'{NS}/plan_info',
                                    lambda m: info(m)['input_stamp_ns'] == ns, 60.0))

    from builtin_interfaces.msg import Time
    threats.publish(cloud([[50.0, 40.0, 50.0]], [1e4], stamp=Time(sec=1)))
    assert 'J' in answer(1)
    start, goal = [10.0, 20.0, 40.0], [90.0, 85.0, 60.0]
    fixes['start_fix'].publish(navsatfix_from_geodetic(*geodetic(start), Time(sec=2)))
    refused = answer(2)
    assert refused['level'] == 'ERROR' and 'datum is empty' in refused['error']
    results = client.set_parameters(f'{NS}/threat_planner', {'datum': DATUM})
    assert results[0].successful, results[0].reason
    fixes['start_fix'].publish(navsatfix_from_geodetic(*geodetic(start), Time(sec=3)))
    assert 'J' in answer(3)
    fixes['goal_fix'].publish(navsatfix_from_geodetic(*geodetic(goal), Time(sec=4)))
    answered = answer(4)
    assert 'J' in answered
    path = path_from_msg(client.wait_for(
        f'{NS}/path', lambda m: stamp_to_ns(m.header.stamp) == int(answered['t0_ns']), 10.0))
    np.testing.assert_allclose(path[0], start, atol=1e-6)
    np.testing.assert_allclose(path[-1], goal, atol=1e-6)
    bad = navsatfix_from_geodetic(*geodetic(goal), Time(sec=5))
    bad.status.status = NavSatStatus.STATUS_NO_FIX
    fixes['goal_fix'].publish(bad)
    assert 'NO_FIX' in answer(5)['error']
    assert proc.poll() is None, log.read_text()
