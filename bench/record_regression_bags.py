"""Re-record the regression bags: ``python -m bench record_regression_bags``, by its old path.

``test/ros/test_replay.py`` tells whoever breaks a replay to run
``.venv/bin/python bench/record_regression_bags.py``; this keeps that command working.
"""

from pathlib import Path
import sys

if __name__ == '__main__':
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from bench.__main__ import main
    sys.exit(main(['record_regression_bags', *sys.argv[1:]]))
