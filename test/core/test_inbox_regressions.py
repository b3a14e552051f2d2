"""Fresh-field cases once planned above the in-box yardstick: within the gate's 1.001 now.

Each scenario in ``test/data/inbox_regressions/`` is a limits-off case of ``python -m bench
fresh`` whose plan was above the in-box yardstick's J by more than the gate's worst
allowed (1.005); that J is in its description. Each was a basin of a lattice route: a
surface route the lattice ranked below others (``best.FREE_SURFACE_ROUTES``) or a route
through the whole box's lattice (``seeds.volume_routes``).
"""

from pathlib import Path
import re

import pytest

from threat_planner import plan, PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario

DATA = Path(__file__).resolve().parents[1] / 'data' / 'inbox_regressions'
CASES = sorted(DATA.glob('*.yaml'))
LIMITS_OFF = {'max_climb_deg': 90.0, 'max_dive_deg': 90.0, 'min_turn_radius_m': 0.0}


@pytest.mark.parametrize('path', CASES, ids=[p.stem for p in CASES])
def test_within_the_in_box_yardstick(path):
    sc = load_scenario(path)
    text = ' '.join(sc.description.split())
    w = float(re.search(r'_w(\d)p(\d+)_off$', path.stem).expand(r'\1.\2'))
    yardstick = float(re.search(r'in-box yardstick J ([0-9.]+)', text)[1])
    r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w, **LIMITS_OFF))
    assert r.feasible and r.seed.startswith(('surface route', 'volume route'))
    assert r.cost.J <= 1.001 * yardstick, f'J {r.cost.J:.4f} against {yardstick:.4f}'


def test_the_cases_are_there():
    assert len(CASES) == 6
