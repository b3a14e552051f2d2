"""The README's main job: the live demo runs the node and the publisher and prints plans."""

from pathlib import Path
import signal
import subprocess
import sys

from node_harness import domain_id, ros_env

DATA = Path(__file__).resolve().parents[1] / 'data'


def test_live_demo_prints_replans_and_writes_the_last_figure(tmp_path):
    """Ctrl-C once the plans are in (the README's way to stop it) ends it with the figure."""
    figure = tmp_path / 'last.png'
    # A fixed --duration had to cover a slow start on a busy machine and so idled for most
    # of its 12 s on a quiet one; --duration stays as a generous cap.
    p = subprocess.Popen(
        [sys.executable, '-m', 'threat_planner.cli.demo', '--scenario',
         str(DATA / 'uniform20_0.yaml'), '--method', 'paper', '--rate', '2', '--drift', '2',
         '--duration', '60', '--figure', str(figure)],
        # stderr (the nodes' logs) in the same pipe: a second one nobody reads until the
        # end could fill and hold the demo.
        env=ros_env(domain_id(31)), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        lines = []
        for line in p.stdout:
            lines.append(line)
            plans = [ln for ln in lines if ln.startswith('plan ')]
            if len(plans) >= 3 and len({ln.split('J=')[1].split()[0] for ln in plans}) >= 2:
                p.send_signal(signal.SIGINT)
                break
        rest, _ = p.communicate(timeout=90)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    stdout = ''.join(lines) + rest
    assert p.returncode == 0, stdout
    plans = [line for line in stdout.splitlines() if line.startswith('plan ')]
    # Drifting threats at 2 Hz: the node replans, each plan line carries J and its time.
    assert len(plans) >= 3, stdout
    assert all(' J=' in line and ' ms' in line for line in plans)
    assert len({line.split('J=')[1].split()[0] for line in plans}) >= 2
    assert figure.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
