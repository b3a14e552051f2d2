"""Shared test set-up: the helper modules (node_harness, a folder's own) import from any folder.

pytest puts a test file's folder on the path when it collects it; a test that imports a
helper of another folder (test/ros/test_node_full_disk.py takes test/bag's disk tools)
must not depend on which folder was collected first.
"""

from pathlib import Path
import signal
import sys

HERE = Path(__file__).resolve().parent
for folder in [HERE] + sorted(p for p in HERE.iterdir() if p.is_dir() and p.name != 'data'):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

# A suite started in the background of a non-interactive shell (`make test &`, nohup)
# inherits SIGINT ignored, and so would every process it starts: the node and batch tests
# that stop a child with Ctrl-C then saw it run on (exit 0). A caught signal is reset to
# the default in a child at exec, so catching it here gives every child the default.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
