"""Three planners in their own namespaces on one domain: no cross-talk, shared pictures."""

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import PointCloud2

from node_harness import (cloud, domain_id, info, planner_command, PYTHON, REPO, RosClient,
                          start_process, stop_process)
from threat_planner.core.inputs.scenario import load_scenario

DOMAIN = domain_id(55)
SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')


def test_three_namespaced_planners_do_not_cross_talk(tmp_path):
    client = RosClient(DOMAIN, 'test_fleet_client')
    procs = []
    try:
        for ns in ('/uav1', '/uav2'):
            procs.append(start_process(planner_command(ns, {'method': 'paper'}), DOMAIN,
                                       tmp_path / f'{ns[1:]}.log'))
        # uav3 takes its picture from the shared topic through remapping.
        cmd = planner_command('/uav3', {'method': 'paper'})
        cmd += ['-r', '/uav3/threats:=/shared/threats']
        procs.append(start_process(cmd, DOMAIN, tmp_path / 'uav3.log'))
        for ns in ('/uav1', '/uav2', '/uav3'):
            client.subscribe(f'{ns}/plan_info', DiagnosticArray)
        pos, f = SCENARIO.threats.positions, SCENARIO.threats.intensities
        client.publisher('/uav1/threats', PointCloud2).publish(cloud(pos[:5], f[:5]))
        client.publisher('/shared/threats', PointCloud2).publish(cloud(pos, f))
        got1 = info(client.wait_for('/uav1/plan_info', timeout=30.0))
        got3 = info(client.wait_for('/uav3/plan_info', timeout=30.0))
        assert got1['threats'] == '5' and got1['input_source'] == '/uav1/threats'
        assert got3['threats'] == '20' and got3['input_source'] == '/shared/threats'
        # uav2 was fed nothing and plans nothing.
        assert client.count('/uav2/plan_info') == 0

        # One threat_publisher feeding uav2 and uav3 at once (uav3 through its remap).
        pub = start_process([PYTHON, '-m', 'threat_planner.ros.publisher', '--ros-args',
                             '-p', f'scenario:={REPO}/test/data/uniform20_0.yaml',
                             '-p', 'namespaces:=[/uav2, /shared]'], DOMAIN,
                            tmp_path / 'pub.log')
        procs.append(pub)
        got2 = info(client.wait_for('/uav2/plan_info', timeout=30.0))
        # The publisher's picture, start and goal come in one burst: the node plans the
        # newest input it holds when its worker is free, so its first plan may name the
        # picture or a later pose (the goal in 1 of 5 runs on a busy machine), uav2's own.
        assert got2['threats'] == '20'
        assert got2['input_source'] in ('/uav2/threats', '/uav2/start', '/uav2/goal_pose')
        assert all(info(m)['input_source'].startswith('/uav1')
                   for _, m in client.messages['/uav1/plan_info'])
    finally:
        codes = [stop_process(p) for p in procs]
        client.close()
    assert codes == [0] * len(procs), [p.read_text() for p in tmp_path.glob('*.log')]
