"""Shared test set-up: the helper modules (node_harness, a folder's own) import from any folder.

pytest puts a test file's folder on the path when it collects it; a test that imports a
helper of another folder (test/ros/test_node_full_disk.py takes test/bag's disk tools)
must not depend on which folder was collected first.
"""

import compileall
import os
from pathlib import Path
import signal
import sys

HERE = Path(__file__).resolve().parent
for folder in [HERE] + sorted(p for p in HERE.iterdir() if p.is_dir() and p.name != 'data'):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

# This machine sets PYTHONDONTWRITEBYTECODE=1 (see bench/suites/cli_scale.py), so each of
# the suite's child processes (some 200 nodes, CLI runs and import probes) compiled the
# package from source again: byte-compiled here once, they load it as an installed copy
# (pip and colcon byte-compile it). compileall writes whatever that flag says, and a
# module edited since is compiled again (its timestamp no longer matches).
compileall.compile_dir(str(HERE.parent / 'threat_planner'), quiet=1)

# The suite's own numpy and scipy work (the yardsticks' SLSQP, reference costs) on one
# BLAS thread, as plan() runs its own: with both cores busy a 2-thread OpenBLAS spins
# against the load (test_yardstick.py beside two busy loops: 90 s, one thread: 23 s).
# OpenBLAS reads the variable once, when numpy and scipy load it; the child processes
# (nodes, CLI runs) keep the environment they would have had.
_blas_env = os.environ.get('OPENBLAS_NUM_THREADS')
os.environ['OPENBLAS_NUM_THREADS'] = '1'
import numpy  # noqa: E402, F401, I100 - loads numpy's OpenBLAS under the limit
import scipy.linalg  # noqa: E402, F401 - and scipy's
if _blas_env is None:
    del os.environ['OPENBLAS_NUM_THREADS']
else:
    os.environ['OPENBLAS_NUM_THREADS'] = _blas_env

# A suite started in the background of a non-interactive shell (`make test &`, nohup)
# inherits SIGINT ignored, and so would every process it starts: the node and batch tests
# that stop a child with Ctrl-C then saw it run on (exit 0). A caught signal is reset to
# the default in a child at exec, so catching it here gives every child the default.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
