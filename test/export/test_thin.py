"""--max-waypoints: thinning keeps the plan's flight limits and zone clearances.

Where plain Douglas-Peucker (the same insertion order, no rules) cuts a zone or steepens a
climb past the limit, the thinned path does not; the J it reports is the exact J of the
points exported.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from threat_planner.cli.main import main
from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.inputs.settings import NO_LIMITS
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.world.airspace import Airspace, make_zone
from threat_planner.core.world.threats import Box, ThreatField
from threat_planner.errors import InputError, PlanningError
from threat_planner.export.thin import thin_path

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / 'examples' / 'geo' / 'valley.yaml'
NO_THREATS = ThreatField.from_arrays(np.zeros((0, 3)), np.zeros(0))
BOX = Box.from_corners([-100.0, -100.0, 0.0], [100.0, 100.0, 200.0])


def plain_dp(path, n):
    """Douglas-Peucker by insertion: the farthest point from its chord, n points, no rules."""
    keep = [0, len(path) - 1]
    while len(keep) < n:
        best = (-1.0, None)
        for a, b in zip(keep[:-1], keep[1:]):
            for k in range(a + 1, b):
                d = path[b] - path[a]
                t = np.clip((path[k] - path[a]) @ d / (d @ d), 0, 1)
                dist = np.linalg.norm(path[k] - path[a] - t * d)
                best = max(best, (dist, k), key=lambda x: x[0])
        keep = sorted(keep + [best[1]])
    return path[keep]


def around_a_cylinder(n=41):
    """A half circle of radius 30 around a cylinder of radius 25 (limits off)."""
    a = np.linspace(np.pi, 0.0, n)
    path = np.column_stack([30 * np.cos(a), 30 * np.sin(a), np.full(n, 50.0)])
    zone = make_zone('cylinder', 'no_fly_zones[0]', center=[0.0, 0.0], radius=25.0,
                     z_min=0.0, z_max=150.0)
    return path, Airspace((zone,))


def test_thinning_keeps_out_of_a_zone_where_plain_dp_cuts_it():
    path, air = around_a_cylinder()
    cfg = replace(PlannerConfig(), **NO_LIMITS)
    assert air.violations(path) == []
    assert air.violations(plain_dp(path, 3))          # the chord through the cylinder
    thinned = thin_path(path, 6, NO_THREATS, BOX, cfg, air)
    assert len(thinned.points) == 6 and air.violations(thinned.points) == []
    np.testing.assert_array_equal(thinned.points, path[thinned.kept])
    assert thinned.kept[0] == 0 and thinned.kept[-1] == len(path) - 1
    with pytest.raises(PlanningError, match=r"need \d+ of the path's 41 points, more than 2"):
        thin_path(path, 2, NO_THREATS, BOX, cfg, air)


def test_thinning_keeps_the_climb_limit_where_plain_dp_breaks_it():
    # a zigzag climbing 25 deg a segment, then level: plain DP's first point is the top
    # of the climb, 51 deg up from the start
    pts = [[0.0, 0.0, 20.0]]
    for i in range(8):
        x, y, z = pts[-1]
        y1 = 10.0 if i % 2 == 0 else 0.0
        pts.append([x + 4.0, y1, z + np.hypot(4.0, y1 - y) * np.tan(np.radians(25.0))])
    pts += [[pts[-1][0] + 6.0 * k, pts[-1][1], pts[-1][2]] for k in range(1, 13)]
    path = np.array(pts)
    cfg = replace(PlannerConfig(), min_turn_radius_m=0.0)
    limits = FlightLimits.of(cfg)
    assert check_limits(path, limits, 0.0).feasible
    assert 'climb_deg' in check_limits(plain_dp(path, 3), limits, 0.0).violations
    thinned = thin_path(path, 12, NO_THREATS, BOX, cfg)
    assert 2 <= len(thinned.points) <= 12
    assert check_limits(thinned.points, limits, 0.0).feasible


def test_a_short_enough_path_is_exported_as_planned():
    path, air = around_a_cylinder(9)
    t = thin_path(path, 20, NO_THREATS, BOX, PlannerConfig(), air)
    np.testing.assert_array_equal(t.points, path)
    with pytest.raises(InputError, match='max_waypoints: must be an integer >= 2'):
        thin_path(path, 1, NO_THREATS, BOX, PlannerConfig(), air)


def test_cli_thins_the_example_and_reports_the_exported_j(example_run):
    summary = example_run.summary
    exported = summary['exported']
    pts = np.array(exported['path'])
    assert exported['points'] == len(pts) <= 16
    np.testing.assert_array_equal(pts, np.array(summary['path'])[exported['kept']])
    s = load_scenario(EXAMPLE)
    cfg = PlannerConfig()
    # the exact J of the exported points, by the closed form (no masking in this scenario)
    c = path_cost(pts, s.threats.positions, s.threats.intensities, cfg.w)
    assert abs(c.J - exported['cost']['J']) <= 1e-9 * c.J
    printed = f'exported: {len(pts)} of {len(summary["path"])} points, J={c.J:.3f}'
    assert printed in example_run.printed
    assert check_limits(pts, FlightLimits.of(cfg), float(s.box.lo[2])).feasible
    assert s.airspace.violations(pts) == []
    np.testing.assert_allclose(s.datum.to_enu(exported['path_geodetic']), pts, atol=1e-6)


def test_cli_refuses_fewer_than_two_waypoints_in_one_line(capsys):
    assert main(['plan', str(EXAMPLE), '--max-waypoints', '1']) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'max_waypoints: must be >= 2' in err
