"""Fresh-field cases a HEAD once planned above the release: none above it again.

``python -m bench fresh --keep-regressions`` wrote each case above 1.001 of the baseline's
J into ``test/data/fresh_regressions/`` (its w and limits in the name, the baseline's J in
the description). Each is planned here with the default limits or none, as there.
"""

from pathlib import Path
import re

import pytest

from threat_planner import plan, PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario

DATA = Path(__file__).resolve().parents[1] / 'data' / 'fresh_regressions'
CASES = sorted(DATA.glob('*.yaml'))
LIMITS_OFF = {'max_climb_deg': 90.0, 'max_dive_deg': 90.0, 'min_turn_radius_m': 0.0}
#: Above the release still, by the ratio measured when the case's fix was tried; strict,
#: so a case that comes back under the release fails here until it is taken off the list.
STILL_ABOVE: dict[str, str] = {
    # Gate run of d89ec92's tree, seed 1796561117 (bench/results/fresh.md).
    # (uniform_n1000_f0_w0p8_on, 509.356 against the release 489.801, came under it with
    # the sloped routes: 489.64.)
    'fresh_s1796561117_strongweak_n10000_f1_w0p2_on': '1244.040 against 1228.722',
    # Gate run of 0d95003, seed 1796638025 (bench/results/fresh_lattice.md); the first
    # was 658.593 at a855110, before the lattice routes. (uniform_n3000_f1_w0p8_on,
    # 663.999 against 661.759, came under it with the sloped routes: 643.71.)
    'fresh_s1796638025_uniform_n1000_f0_w0p2_off': '657.016 against 653.724',
}


def _case(path: Path) -> tuple[float, bool, float]:
    m = re.search(r'_w(\d)p(\d+)_(on|off)$', path.stem)
    sc = load_scenario(path)
    base = re.search(r'baseline .*? J ([0-9.]+)', ' '.join(sc.description.split()))
    return float(f'{m[1]}.{m[2]}'), m[3] == 'on', float(base[1])


@pytest.mark.parametrize('path', [
    pytest.param(p, id=p.stem, marks=[pytest.mark.xfail(strict=True,
                                                        reason=STILL_ABOVE[p.stem])]
                 if p.stem in STILL_ABOVE else []) for p in CASES])
def test_not_above_the_release(path):
    w, on, base_j = _case(path)
    sc = load_scenario(path)
    cfg = PlannerConfig(w=w) if on else PlannerConfig(w=w, **LIMITS_OFF)
    r = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    assert r.feasible
    assert r.cost.J <= 1.001 * base_j, f'J {r.cost.J:.4f} against the release {base_j:.4f}'


def test_the_cases_are_there():
    assert len(CASES) >= 30
