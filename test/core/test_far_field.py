"""The cut-off optimiser's far field: every threat counted once, the cells close to exact."""

from pathlib import Path

import numpy as np
import pytest

from threat_planner import Box, plan, PlannerConfig, ThreatField
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.cost.far_kernels import far_pairs
from threat_planner.core.world.far_field import FarField

REGRESSIONS = Path(__file__).resolve().parents[1] / 'data' / 'fresh_regressions'


def _field(n: int, seed: int, ground: bool = False) -> tuple[ThreatField, Box, float]:
    rng = np.random.default_rng(seed)
    side = 100 * (n / 20) ** (1 / 3)
    pos = rng.uniform(0.05, 0.95, (n, 3)) * side
    if ground:
        pos[:, 2] = rng.uniform(0.0, 0.1, n) * side
    threats = ThreatField.from_arrays(pos, rng.uniform(1e5, 4e5, n))
    box = Box.from_corners([0, 0, 0], [side] * 3)
    return threats, box, 3.0 * threats.typical_spacing(box)


def _path(box: Box, segments: int = 40) -> np.ndarray:
    side = float(box.hi[0])
    p = np.linspace([0, 0, side / 2], [side, side, side / 2], segments + 1)
    p[1:-1, 2] += 0.2 * side * np.sin(np.linspace(0, np.pi, segments + 1))[1:-1]
    return p


def _brute_jr(a, b, pos, f, seg, idx, samples=200):
    """J_R of each segment by the midpoint rule over the given (segment, threat) pairs."""
    t = (np.arange(samples) + 0.5) / samples
    out = np.zeros(len(a))
    for s in range(len(a)):
        m = seg == s
        pts = a[s] + t[:, None] * (b[s] - a[s])
        d2 = ((pts[:, None, :] - pos[idx[m]][None]) ** 2).sum(axis=2)
        out[s] = (f[idx[m]][None] / d2 ** 2).sum() * np.linalg.norm(b[s] - a[s]) / samples
    return out


@pytest.mark.parametrize('n, seed, ground', [(300, 0, False), (2000, 1, False),
                                             (1000, 2, True)])
def test_every_threat_counted_once_per_segment(n, seed, ground):
    threats, box, radius = _field(n, seed, ground)
    far = FarField(threats.positions, threats.intensities, radius)
    p = _path(box)
    seg, idx = far_pairs(far, p[:-1], p[1:])
    assert np.all(np.diff(seg) >= 0)
    # The F of a segment's pairs is all the F there is: nothing dropped, nothing twice.
    np.testing.assert_allclose(np.bincount(seg, far.intensities[idx], len(p) - 1),
                               threats.total_intensity, rtol=1e-12)
    # Every threat within the cut-off of a segment is among its exact pairs.
    near_seg, near_thr, _ = threats.near_pairs(p[:-1], p[1:], radius)
    exact = set(zip(seg[idx < n].tolist(), idx[idx < n].tolist()))
    assert set(zip(near_seg.tolist(), near_thr.tolist())) <= exact


def _brute_pairs(far: FarField, a: np.ndarray, b: np.ndarray) -> list[list[int]]:
    """Each segment's indices by the definition, one cell or threat at a time.

    A cell counts where it is far (at least the cut-off and OPENING x its extent from the
    segment) and no ancestor is; a threat where no cell holding it is far. Order: the far
    cells from the top level down, ascending within a level; then the threats of the
    leaves, leaf by leaf in ascending order.
    """
    cells, n = len(far.cell_extent), far.n_threats
    parent = np.full(cells, -1)
    level = np.zeros(cells, int)
    for g in range(far.n_leaf, cells):
        kids = far.items[far.first[g]:far.first[g + 1]]
        parent[kids] = g
        level[g] = level[kids[0]] + 1 if len(kids) else 0
    leaf_of = np.empty(n, int)
    for g in range(far.n_leaf):
        leaf_of[far.items[far.first[g]:far.first[g + 1]]] = g
    out = []
    for s in range(len(a)):
        mid, half = 0.5 * (a[s] + b[s]), 0.5 * np.linalg.norm(b[s] - a[s])
        dist = np.linalg.norm(mid - np.clip(mid, far.cell_lo, far.cell_hi), axis=1) - half
        far_cell = (dist >= far.radius) & (dist >= far.opening * far.cell_extent)

        def covered(g):
            while g >= 0:
                if far_cell[g]:
                    return True
                g = parent[g]
            return False
        kept = [g for g in range(cells) if far_cell[g] and not covered(parent[g])]
        kept.sort(key=lambda g: (-level[g], g))
        open_leaves = [g for g in range(far.n_leaf) if not covered(g)]
        threats = [int(i) for g in open_leaves for i in far.items[far.first[g]:far.first[g + 1]]]
        out.append([n + g for g in kept] + threats)
    return out


@pytest.mark.parametrize('n, seed, kind', [(5, 0, 'uniform'), (300, 1, 'uniform'),
                                           (1000, 2, 'flat'), (2000, 3, 'cluster')])
def test_the_compiled_walk_is_the_definition_in_its_order(n, seed, kind):
    rng = np.random.default_rng(seed)
    side = 100 * (n / 20) ** (1 / 3)
    pos = rng.uniform(0.05, 0.95, (n, 3)) * side
    if kind == 'flat':
        pos[:, 2] *= 0.05
    elif kind == 'cluster':
        pos = (rng.normal(size=(n, 3)) * 0.05 + 0.5) * side
    radius = float(rng.uniform(0.5, 3.0)) * side / n ** (1 / 3)
    far = FarField(pos, rng.uniform(1e5, 4e5, n), radius)
    p = np.cumsum(rng.normal(size=(31, 3)) * side / 30, axis=0) + side / 2
    seg, idx = far_pairs(far, p[:-1], p[1:])
    want = _brute_pairs(far, p[:-1], p[1:])
    assert seg.tolist() == [s for s, row in enumerate(want) for _ in row]
    assert idx.tolist() == [i for row in want for i in row]


@pytest.mark.parametrize('n, seed, ground', [(2000, 1, False), (1000, 2, True)])
def test_cells_within_two_percent_of_every_threat_where_the_cutoff_lost_more(n, seed, ground):
    threats, box, radius = _field(n, seed, ground)
    far = FarField(threats.positions, threats.intensities, radius)
    p = _path(box)
    a, b = p[:-1], p[1:]
    every = _brute_jr(a, b, threats.positions, threats.intensities,
                      np.repeat(np.arange(len(a)), n), np.tile(np.arange(n), len(a))).sum()
    seg, idx = far_pairs(far, a, b)
    cells = _brute_jr(a, b, far.positions, far.intensities, seg, idx).sum()
    near_seg, near_thr, _ = threats.near_pairs(a, b, radius)
    cut = _brute_jr(a, b, threats.positions, threats.intensities, near_seg, near_thr).sum()
    assert abs(cells / every - 1) < 0.02
    assert abs(cells - every) < 0.25 * abs(cut - every)


def test_ground_radars_below_the_path_are_not_traded_for_length():
    """1,000 ground radars, w 0.8, no limits: at the in-box yardstick's J, not 25 % above.

    The bench's in-box yardstick (grid routes refined on the exact J) found 137.012 on this
    field; counting only the threats within the cut-off, the optimiser flew the plan down
    towards the radars to 170.74 (4a8b907), further than its own start.
    """
    sc = load_scenario(REGRESSIONS / 'fresh_s1796529962_ground_n1000_f1_w0p8_off.yaml')
    cfg = PlannerConfig(w=0.8, max_climb_deg=90.0, max_dive_deg=90.0, min_turn_radius_m=0.0)
    r = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    assert r.feasible
    assert r.cost.J <= 1.005 * 137.012
