"""Shared test set-up: the helpers beside this file (node_harness) import from any folder."""

from pathlib import Path
import sys

HERE = str(Path(__file__).resolve().parent)
if HERE not in sys.path:
    sys.path.insert(0, HERE)
