"""Fly end to end: pop-up, move, removal and a new goal, checked from the flown path alone.

Every check here recomputes from ``FlightReport.times`` and ``.path``: the climb angles
and turn radii from consecutive flown points, J_flown by brute-force quadrature of
F / d^4 along the flown polyline with each threat where it truly was at each moment (an
independent model of the events, not the project's timeline), the lethal sphere by the
flown segments' own distances to its centre.
"""

from dataclasses import replace
import math
from pathlib import Path

import numpy as np
import pytest

from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan
from threat_planner.flight.events import parse_events
from threat_planner.flight.fly import fly

DATA = Path(__file__).resolve().parents[1] / 'data'
SPEED = 20.0
#: The pop-up: when, its lethal radius, and how long after the end of the commit it
#: triggers the vehicle would have been at its centre.
T_POP, LETHAL = 2.0, 8.0
POP_AHEAD_S = 1.5
#: Threat 5 of the scenario flies from take-off (the scenario key ``velocity``).
MOVER_VELOCITY = [0.0, -4.0, 1.0]


@pytest.fixture(scope='module')
def scenario():
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    vel = np.zeros((len(sc.threats), 3))
    vel[5] = MOVER_VELOCITY
    return replace(sc, velocities=vel)


@pytest.fixture(scope='module')
def undisturbed(scenario):
    """The flight without events: the path the pop-up is put on."""
    return fly(scenario, [], PlannerConfig(), SPEED, hindsight=False)


@pytest.fixture(scope='module')
def events_doc(undisturbed):
    """Pop-up with a lethal radius ahead on the path at 2 s, move at 3, removal at 4, goal."""
    t = T_POP + PlannerConfig().commit_s + POP_AHEAD_S
    where = np.array([np.interp(t, undisturbed.times, undisturbed.path[:, c])
                      for c in range(3)])
    return {'events': [
        {'t': T_POP, 'add_threat': {'position': where.tolist(), 'intensity': 2.0e5,
                                    'lethal_radius': LETHAL}},
        {'t': 3.0, 'move_threat': {'index': 10, 'position': [60.0, 60.0, 60.0],
                                   'velocity': [-6.0, 3.0, 0.0]}},
        {'t': 4.0, 'remove_threat': {'index': 3}},
        {'t': 5.0, 'goal': [100.0, 85.0, 55.0]},
    ]}


@pytest.fixture(scope='module')
def flight(scenario, events_doc):
    return fly(scenario, parse_events(events_doc), PlannerConfig(), SPEED)


class Truth:
    """Where each threat is at time t: the scenario moved and changed by the events."""

    def __init__(self, scenario, events_doc):
        # One row per straight piece: id, F, origin, velocity, t_on, t_off.
        self.rows = [[i, float(f), np.array(p, float), np.array(v, float), 0.0, math.inf]
                     for i, (p, f, v) in enumerate(zip(scenario.threats.positions,
                                                       scenario.threats.intensities,
                                                       scenario.velocities))]
        self.n = len(self.rows)
        self.lethal = {}
        self.appeared = {}
        for e in events_doc['events']:
            t = e['t']
            if 'add_threat' in e:
                a = e['add_threat']
                self.rows.append([self.n, a['intensity'], np.array(a['position'], float),
                                  np.array(a.get('velocity', [0, 0, 0]), float), t, math.inf])
                self.lethal[self.n] = a.get('lethal_radius')
                self.appeared[self.n] = t
                self.n += 1
            elif 'move_threat' in e or 'remove_threat' in e:
                m = e.get('move_threat') or e['remove_threat']
                row = next(r for r in self.rows if r[0] == m['index'] and r[5] == math.inf)
                row[5] = t
                if 'move_threat' in e:
                    here = row[2] + row[3] * (t - row[4])
                    self.rows.append([row[0], row[1],
                                      np.array(m.get('position', here), float),
                                      np.array(m.get('velocity', row[3]), float), t,
                                      math.inf])

    def changes(self):
        return sorted({r[4] for r in self.rows} | {r[5] for r in self.rows} - {math.inf})

    def threat_cost_density(self, x, t):
        """Sum of F / d^4 at points `x` (K, 3) flown at times `t` (K,)."""
        out = np.zeros(len(t))
        for _, f, origin, vel, on, off in self.rows:
            live = (t >= on) & (t < off)
            q = origin + vel * (t - on)[:, None]
            d2 = np.sum((x - q) ** 2, axis=1)
            out += np.where(live, f / np.where(live, d2, 1.0) ** 2, 0.0)
        return out


def _quadrature_j(times, path, truth, w, nodes=16, parts=4):
    """J = w J_R + (1 - w) J_L by Gauss-Legendre on every flown segment, split at changes."""
    u, wts = np.polynomial.legendre.leggauss(nodes)
    changes = np.array(truth.changes())
    j_r, j_l = 0.0, 0.0
    for k in range(len(times) - 1):
        a, b, ta, tb = path[k], path[k + 1], times[k], times[k + 1]
        length = float(np.linalg.norm(b - a))
        j_l += length
        cuts = np.concatenate([[ta], changes[(changes > ta) & (changes < tb)], [tb]])
        for c0, c1 in zip(cuts[:-1], cuts[1:]):
            edges = np.linspace(c0, c1, parts + 1)
            mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
            t = (mid[:, None] + half[:, None] * u[None]).ravel()
            wt = (half[:, None] * wts[None]).ravel()
            frac = (t - ta) / (tb - ta)
            x = a + frac[:, None] * (b - a)
            # ds = length / (tb - ta) dt along the segment.
            j_r += float(np.sum(wt * truth.threat_cost_density(x, t))) * length / (tb - ta)
    return w * j_r + (1.0 - w) * j_l, j_l, j_r


def _circumradii(p):
    a, b, c = p[:-2], p[1:-1], p[2:]
    ab = np.linalg.norm(b - a, axis=1)
    bc = np.linalg.norm(c - b, axis=1)
    ca = np.linalg.norm(a - c, axis=1)
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    with np.errstate(divide='ignore'):
        return np.where(area2 > 1e-12 * ab * bc, ab * bc * ca / (2.0 * area2), np.inf)


def _segment_distance(a, b, c):
    """Distance of point `c` from each segment a[k]-b[k]."""
    d = b - a
    d2 = np.maximum(np.einsum('ij,ij->i', d, d), 1e-300)
    s = np.clip(np.einsum('ij,ij->i', c - a, d) / d2, 0.0, 1.0)
    return np.linalg.norm(a + s[:, None] * d - c, axis=1)


def test_the_flight_reaches_the_new_goal(flight, events_doc):
    assert flight.reached_goal
    assert np.linalg.norm(flight.path[-1] - events_doc['events'][-1]['goal']) <= 1.0


def test_the_flown_path_is_sampled_at_most_every_tenth_of_a_second(flight):
    dt = np.diff(flight.times)
    assert flight.times[0] == 0.0 and dt.min() > 0.0 and dt.max() <= 0.1 + 1e-12
    steps = np.linalg.norm(np.diff(flight.path, axis=0), axis=1)
    assert steps == pytest.approx(SPEED * dt, rel=1e-9)      # at cruise speed throughout


def test_each_event_replans_and_the_path_never_jumps(flight):
    assert [r['reason'].split(' ')[0] for r in flight.replans] == [
        'start', 'add_threat', 'move_threat', 'remove_threat', 'goal']
    assert flight.max_jump_m <= 0.5


def test_every_replan_succeeds(flight):
    # The turn-in used to leave the box (2.66 m) and a later commit point was outside it.
    assert [r.get('error') for r in flight.replans] == [None] * 5


def test_climb_dive_and_turn_limits_hold_along_the_flown_path(flight):
    cfg = PlannerConfig()
    step = np.diff(flight.path, axis=0)
    climb = np.degrees(np.arctan2(step[:, 2], np.hypot(step[:, 0], step[:, 1])))
    assert climb.max() <= cfg.max_climb_deg + 1e-6
    assert -climb.min() <= cfg.max_dive_deg + 1e-6
    # Whole steps only: the last one ends where the goal is passed, part of a step.
    whole = flight.path[:-1] if len(flight.path) > 3 else flight.path
    assert _circumradii(whole).min() >= cfg.min_turn_radius_m * (1 - 1e-6)


def test_j_flown_is_the_quadrature_of_the_true_threats_along_the_flown_path(
        flight, scenario, events_doc):
    cfg = PlannerConfig()
    truth = Truth(scenario, events_doc)
    j, j_l, j_r = _quadrature_j(flight.times, flight.path, truth, cfg.w)
    assert flight.flown.J_L == pytest.approx(j_l, rel=1e-12)
    assert flight.flown.J_R == pytest.approx(j_r, rel=1e-8)
    assert flight.flown.J == pytest.approx(j, rel=1e-8)
    # The threats' motion counts: the same path against the t = 0 picture differs.
    still = Truth(replace(scenario, velocities=None), {'events': []})
    assert abs(_quadrature_j(flight.times, flight.path, still, cfg.w)[0] - j) > 1e-3 * j


def test_the_flown_path_keeps_out_of_the_pop_up_s_lethal_sphere(flight, events_doc,
                                                                undisturbed):
    pop = events_doc['events'][0]['add_threat']
    centre = np.array(pop['position'])
    # Without it the vehicle flies through its centre (where it was put).
    assert _segment_distance(undisturbed.path[:-1], undisturbed.path[1:], centre).min() < 1e-9
    after = flight.times[1:] > T_POP    # segments flown once the threat is there
    d = _segment_distance(flight.path[:-1][after], flight.path[1:][after], centre)
    assert d.min() >= LETHAL
    assert flight.lethal == []


def test_a_flight_without_events_flies_the_static_plan(scenario):
    still = replace(scenario, velocities=None)
    cfg = PlannerConfig()
    static = plan(still.threats, still.start, still.goal, still.box, cfg)
    report = fly(still, [], cfg, SPEED)
    assert report.reached_goal
    assert len(report.replans) == 1 and report.max_jump_m == 0.0
    assert report.hindsight.J == pytest.approx(static.cost.J, rel=1e-12)
    # The vehicle cuts the plan's corners a little (pure pursuit within the limits).
    assert report.flown.J == pytest.approx(static.cost.J, rel=0.02)
    assert report.flown.J_L == pytest.approx(static.cost.J_L, rel=0.02)
    assert report.times[-1] == pytest.approx(static.eta_s, rel=0.02)
