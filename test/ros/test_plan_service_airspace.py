"""``plan_path`` in an airspace: a goal inside a no-fly zone is refused, a good request's
path avoids the zones (the service plans with the node's airspace)."""

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.srv import GetPlan
from sensor_msgs.msg import PointCloud2
import yaml

from node_harness import (cloud, domain_id, planner_command, pose, REPO, RosClient,
                          start_process, stop_process)
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.world.airspace import Airspace
from threat_planner.ros.conversions import path_from_msg

SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')
ZONE = {'type': 'sphere', 'center': [50.0, 50.0, 50.0], 'radius': 12.0}


def test_goal_in_a_zone_is_refused_and_paths_avoid_the_zones(tmp_path):
    domain = domain_id(160)
    airspace_file = tmp_path / 'airspace.yaml'
    airspace_file.write_text(yaml.safe_dump({'no_fly_zones': [ZONE]}))
    log = tmp_path / 'node.log'
    proc = start_process(planner_command('/svcair', {'airspace_file': str(airspace_file)}),
                         domain, log)
    client = RosClient(domain, 'svc_air_client')
    try:
        client.subscribe('/svcair/plan_info', DiagnosticArray)
        pub = client.publisher('/svcair/threats', PointCloud2)
        client.wait_matched(pub, timeout=30.0)
        pub.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities))
        client.wait_for('/svcair/plan_info', timeout=60.0)
        cli = client.node.create_client(GetPlan, '/svcair/plan_path')
        assert cli.wait_for_service(timeout_sec=20.0)

        def ask(goal):
            f = cli.call_async(GetPlan.Request(start=pose([0.0, 0.0, 50.0]),
                                               goal=pose(goal)))
            client.wait_until(f.done, 60.0, 'plan_path answer')
            return f.result().plan

        refused = ask([50.0, 50.0, 50.0])
        assert refused.poses == []
        client.wait_until(lambda: 'inside' in log.read_text(), 5.0, 'the logged reason')
        good = path_from_msg(ask([100.0, 100.0, 50.0]))
        air = Airspace.from_mapping({'no_fly_zones': [ZONE]}, base=tmp_path)
        assert len(good) > 2 and not air.violations(good)
    finally:
        client.close()
        assert stop_process(proc) == 0, log.read_text()
