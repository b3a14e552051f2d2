"""Shared test set-up: the helper modules (node_harness, a folder's own) import from any folder.

pytest puts a test file's folder on the path when it collects it; a test that imports a
helper of another folder (test/ros/test_node_full_disk.py takes test/bag's disk tools)
must not depend on which folder was collected first.
"""

from pathlib import Path
import sys

HERE = Path(__file__).resolve().parent
for folder in [HERE] + sorted(p for p in HERE.iterdir() if p.is_dir() and p.name != 'data'):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))
