"""How far J moves when every threat moves by a nanometre: the planner's rounding sensitivity.

Usage (from the repository root)::

    .venv/bin/python bench/run_perturbation.py [--out bench/results/perturbation.md]

A nanometre is far below any measurement of a radar's position, so a plan that changes
with it changes with rounding: with a different CPU, libm or kernel arithmetic. Each case
(the 21 bundled 20-threat cases and ``run_random_fields``' 45 fresh fields, limits on and
off) is planned cold as given and NUDGES times with every threat moved 1e-9 m in random
directions (seeded); the report gives each J(moved) / J(given) and how many cases moved
by more than 0.1 % in any of them. Both J are exact; the moved field is a different
problem by 1e-9 m, so a change of J beyond ~1e-9 relative is the planner taking another
basin or stopping elsewhere, not the cost changing.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import statistics
import time

import numpy as np

import _repo  # puts the repository root on sys.path first
import run_random_fields
from run_speed import SCENARIOS, WS   # the bundled 20-threat cases the speed bench plans
from threat_planner import load_scenario, plan, PlannerConfig
from threat_planner.core.inputs.settings import NO_LIMITS
from threat_planner.core.world.threats import ThreatField

OUT = _repo.ROOT / 'bench' / 'results' / 'perturbation.md'
#: How far every threat moves [m].
NUDGE = 1e-9
#: Nudged fields per case.
NUDGES = 3
#: A case "moved" when J changed by more than this fraction.
MOVED = 1e-3


def cases():
    """(name, threats, start, goal, box, w) of the bundled and the fresh cases."""
    for name in SCENARIOS:
        sc = load_scenario(_repo.ROOT / 'test' / 'data' / f'{name}.yaml')
        for w in WS:
            yield f'{name}@{w}', sc.threats, sc.start, sc.goal, sc.box, w
    yield from run_random_fields.fields()


def nudged(threats: ThreatField, seed: int) -> ThreatField:
    """The field with every threat moved NUDGE [m] in a random direction."""
    d = np.random.default_rng(seed).normal(size=threats.positions.shape)
    d *= NUDGE / np.linalg.norm(d, axis=1)[:, None]
    return ThreatField.from_arrays(threats.positions + d, threats.intensities)


def run() -> list[dict]:
    """Plan every case as given and nudged, limits on and off."""
    rows = []
    for k, (name, threats, s, t, box, w) in enumerate(cases()):
        fields = [nudged(threats, NUDGES * k + i) for i in range(NUDGES)]
        for label, lim in (('on', {}), ('off', NO_LIMITS)):
            cfg = PlannerConfig(w=w, **lim)
            given = plan(threats, s, t, box, cfg)
            others = [plan(f, s, t, box, cfg) for f in fields]
            ratios = [o.cost.J / given.cost.J for o in others]
            far = max(range(NUDGES), key=lambda i: abs(ratios[i] - 1.0))
            rows.append({'case': name, 'limits': label, 'J': given.cost.J,
                         'ratios': ratios, 'J_moved': others[far].cost.J,
                         'seed': given.seed, 'seed_moved': others[far].seed})
            print(name, label, ' '.join(f'{x:.4f}' for x in ratios), flush=True)
    return rows


def markdown(rows: list[dict]) -> str:
    """Render perturbation.md."""
    lines = ['# J under a 1 nm move of every threat', '',
             f'Written by `bench/run_perturbation.py` on {time.strftime("%Y-%m-%d")} '
             f'(`{_repo.short_commit(_repo.ROOT)}`). Every threat moved {NUDGE:g} m in a '
             f'random direction, {NUDGES} such fields per case; cold plans of `best`; '
             'ratio = J(moved) / J(given), both exact. A ratio away from 1 is the planner '
             'ending in another basin or elsewhere in one: a change of rounding (CPU, libm, '
             'kernel arithmetic) does the same.', '',
             '| limits | cases | cases moved > 0.1 % | plans up | plans down | median | '
             'least | largest |',
             '|---|---:|---:|---:|---:|---:|---:|---:|']
    for label in ('on', 'off'):
        mine = [row for row in rows if row['limits'] == label]
        r = [x for row in mine for x in row['ratios']]
        moved = sum(any(abs(x - 1) > MOVED for x in row['ratios']) for row in mine)
        up = sum(x > 1 + MOVED for x in r)
        down = sum(x < 1 - MOVED for x in r)
        lines.append(f'| {label} | {len(mine)} | {moved} | {up} | {down} | '
                     f'{statistics.median(r):.4f} | {min(r):.4f} | {max(r):.4f} |')
    lines += ['', '## Cases that moved by more than 0.1 %', '',
              '| case | limits | J | ratios | J moved (farthest) | seed | its seed |',
              '|---|---|---:|---|---:|---|---|']
    for row in rows:
        if any(abs(x - 1) > MOVED for x in row['ratios']):
            ratios = ' / '.join(f'{x:.4f}' for x in row['ratios'])
            lines.append(f'| {row["case"]} | {row["limits"]} | {row["J"]:.2f} | {ratios} | '
                         f'{row["J_moved"]:.2f} | {row["seed"]} | {row["seed_moved"]} |')
    return '\n'.join(lines) + '\n'


def main() -> None:
    """Run the cases and write the report."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--out', type=Path, default=OUT)
    args = ap.parse_args()
    args.out.write_text(markdown(run()))
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
