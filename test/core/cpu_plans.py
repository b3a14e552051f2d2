"""Plan a set of fields and print each J and path as JSON (run by test_same_on_every_cpu).

The bundled scenarios without airspace (the airspace method's SLSQP sums with the BLAS
of its own CPU) at w 0.2 / 0.5 / 0.8 with the limits on, at w 0.5 without them, the
paper's two methods on uniform20_0, and bench perturbation's n20 seed 1 w 0.8 (20 random
threats, start and goal at opposite corners), which planned J 399.15 on OpenBLAS's
SkylakeX kernels and 395.81 on its Haswell ones before core/_vector.py.
"""

import glob
import json
import os

import numpy as np

from threat_planner.core import load_scenario, plan, PlannerConfig
from threat_planner.core.inputs.settings import NO_LIMITS
from threat_planner.core.world.threats import Box, ThreatField

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data')


def corner_switchback():
    """bench perturbation's n20 seed 1 w 0.8: threats, start, goal and box."""
    rng = np.random.default_rng([101, 20])
    positions, intensities = rng.uniform(0.0, 100.0, (20, 3)), rng.uniform(1e5, 4e5, 20)
    rng = np.random.default_rng([20, 1])
    s = np.array([0.0, 0.0, rng.uniform(0.0, 100.0)])
    t = np.array([100.0, 100.0, rng.uniform(0.0, 100.0)])
    threats = ThreatField.from_arrays(positions, intensities * rng.uniform(0.3, 3.0, 20))
    return threats, s, t, Box.from_corners([0.0] * 3, [100.0] * 3)


def main() -> None:
    out = {}
    for path in sorted(glob.glob(os.path.join(DATA, '*.yaml'))):
        sc = load_scenario(path)
        name = os.path.basename(path)[:-5]
        if sc.airspace or name == 'big300_0':
            continue
        runs = [(f'{name}@{w} on', PlannerConfig(w=w)) for w in (0.2, 0.5, 0.8)]
        runs.append((f'{name}@0.5 off', PlannerConfig(w=0.5, **NO_LIMITS)))
        if name == 'uniform20_0':
            runs += [(f'{name}@0.5 {m}', PlannerConfig(w=0.5, method=m))
                     for m in ('paper', 'improved')]
        for key, cfg in runs:
            r = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
            out[key] = [r.cost.J, r.path.tolist()]
    threats, s, t, box = corner_switchback()
    r = plan(threats, s, t, box, PlannerConfig(w=0.8))
    out['n20 seed 1 w 0.8 on'] = [r.cost.J, r.path.tolist()]
    print(json.dumps(out))


if __name__ == '__main__':
    main()
