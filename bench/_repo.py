"""Put the repository root on ``sys.path`` so the bench scripts import ``threat_planner``.

Imported for its side effect by every script under ``bench/`` (they run as
``python bench/<script>.py``, which puts ``bench/`` itself, not the root, on the path).
"""

from pathlib import Path
import sys

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
