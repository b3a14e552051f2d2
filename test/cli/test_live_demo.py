"""The README's main job: the live demo runs the node and the publisher and prints plans."""

from pathlib import Path
import subprocess
import sys

from node_harness import domain_id, ros_env

DATA = Path(__file__).resolve().parents[1] / 'data'


def test_live_demo_prints_replans_and_writes_the_last_figure(tmp_path):
    figure = tmp_path / 'last.png'
    p = subprocess.run(
        [sys.executable, '-m', 'threat_planner.cli.demo', '--scenario',
         str(DATA / 'uniform20_0.yaml'), '--method', 'paper', '--rate', '2', '--drift', '2',
         '--duration', '12', '--figure', str(figure)],
        env=ros_env(domain_id(31)), capture_output=True, text=True, timeout=90)
    assert p.returncode == 0, p.stdout + p.stderr
    plans = [line for line in p.stdout.splitlines() if line.startswith('plan ')]
    # Drifting threats at 2 Hz: the node replans, each plan line carries J and its time.
    assert len(plans) >= 3, p.stdout
    assert all(' J=' in line and ' ms' in line for line in plans)
    assert len({line.split('J=')[1].split()[0] for line in plans}) >= 2
    assert figure.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
