"""Put the repository root on ``sys.path`` so the bench scripts import ``threat_planner``.

Imported for its side effect by every script under ``bench/`` (they run as
``python bench/<script>.py``, which puts ``bench/`` itself, not the root, on the path);
also names a checkout's commit for the reports that compare two.
"""

from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def short_commit(tree: Path) -> str:
    """Abbreviated commit of a checkout's HEAD ('' outside git)."""
    return subprocess.run(['git', '-C', str(tree), 'rev-parse', '--short', 'HEAD'],
                          capture_output=True, text=True).stdout.strip()
