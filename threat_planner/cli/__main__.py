import sys

from threat_planner.cli import main

sys.exit(main())
