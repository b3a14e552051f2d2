"""``python -m threat_planner.cli``: the ``threat-planner`` script."""

from threat_planner.cli.main import console

console()
