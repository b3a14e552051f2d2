"""``threat-planner fly``: a simulated flight through an events file; ``--start-heading``.

``fly SCENARIO --events EVENTS.yaml`` flies the scenario with
:func:`threat_planner.flight.fly.fly` (the point-mass vehicle, events applied at their
times, a replan after each), prints the replans and their latencies, the flown cost
against the plan made with hindsight, the largest jump of the commanded path and the
limits met along the flown path; ``--json`` writes :meth:`FlightReport.as_dict` (every
non-finite number as null), ``--plot`` a top and a side view (:mod:`.flight_figure`).

``--record flight.mcap`` records the flight as a bag
(:mod:`threat_planner.ros.recording.flight_record`) that ``threat-planner replay`` flies
again.

``--start-heading`` (``fly`` and ``plan``) is the direction the vehicle flies at the start:
three numbers (a vector) or two (yaw and pitch [deg]). ``plan`` then brings its path onto
it with :func:`threat_planner.core.flight.entry.enter` and reports that path's exact J.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
import json
import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.cli.options import config_from, output_file
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario, Scenario
from threat_planner.core.result import PlanResult
from threat_planner.errors import InputError

__all__ = ['HeadedPlan', 'add_fly_command', 'add_start_heading', 'enter_plan',
           'flight_lines', 'refuse_heading_with', 'start_heading']


def add_start_heading(parser: argparse.ArgumentParser) -> None:
    """Add ``--start-heading`` (a vector, or yaw and pitch in degrees) to `parser`."""
    parser.add_argument('--start-heading', nargs='+', type=float, metavar='H',
                        help='direction the vehicle flies at the start: X Y Z (a vector) or '
                             'YAW PITCH [deg]; the path leaves along it with its first turn '
                             'within the limits')


def start_heading(args: argparse.Namespace) -> NDArray | None:
    """Return ``--start-heading`` as a unit vector, None without it.

    Raises
    ------
    InputError
        Naming ``start_heading`` for a wrong count, a non-finite or a zero value.

    """
    from threat_planner.core.flight.entry import unit_heading
    value = getattr(args, 'start_heading', None)
    return None if value is None else unit_heading(value, 'start_heading')


def add_fly_command(sub, planner_options) -> None:
    """Add the ``fly`` subcommand to `sub` (`planner_options` adds SCENARIO and settings)."""
    p = sub.add_parser(
        'fly', help='fly a simulated vehicle through an events file, replanning in flight',
        description='Plan at t = 0, fly a point mass at --speed along the plan within the '
                    'turn, climb and dive limits, and replan after each event of the '
                    'events file (threats that pop up, move or leave; zones; the goal), '
                    'keeping --commit seconds of the path ahead. Exit status 2: bad input.')
    planner_options(p)
    p.add_argument('--events', required=True, metavar='EVENTS.yaml',
                   help='events file: {events: [{t: 2.0, add_threat: {...}}, ...]} '
                        '(docs/flight.md)')
    add_start_heading(p)
    p.add_argument('--json', metavar='OUT.json',
                   help='write the flight (flown path and times, replans, costs) as JSON')
    p.add_argument('--plot', metavar='flight.png',
                   help='write a top view and a side view of the flight (PNG)')
    p.add_argument('--record', metavar='flight.mcap',
                   help='record the flight to MCAP as the planner node, threat_publisher '
                        'and sim_vehicle would (threats, events, path, plan_info, odom) '
                        'with its setup; threat-planner replay flies it again (docs/bags.md)')
    p.add_argument('--record-no-latency', action='store_true',
                   help='leave the wall-clock replan latencies out of the recording: the '
                        'same flight then records to the same bytes')
    p.set_defaults(func=_cmd_fly)


def _events(path: str) -> list:
    from threat_planner.flight.events import load_events
    try:
        return load_events(path)
    except InputError as exc:
        text = str(exc)
        # A file's own problem names the file already; a field's gets it in front.
        raise InputError(text if text.startswith('events:') else f'{path}: {text}') from None


def _cmd_fly(args: argparse.Namespace) -> int:
    from threat_planner.flight.fly import finite_json, fly
    scenario = load_scenario(args.scenario)
    cfg = config_from(args, scenario)
    heading = start_heading(args)
    events = _events(args.events)
    recorded = None
    if args.record:
        from threat_planner.ros.recording.flight_record import record_flight
        report, recorded = record_flight(scenario, events, cfg, cfg.speed_mps, args.record,
                                         latency=not args.record_no_latency,
                                         commit_s=cfg.commit_s, heading=heading)
    else:
        report = fly(scenario, events, cfg, cfg.speed_mps, commit_s=cfg.commit_s,
                     heading=heading)
    for line in flight_lines(scenario, cfg, events, report):
        print(line)
    if recorded is not None:
        print(f'  recorded: {recorded}')
    if args.json:
        data = {'scenario': scenario.name, 'events_file': str(args.events),
                'commit_s': cfg.commit_s, 'w': cfg.w,
                'start_heading': None if heading is None else heading.tolist(),
                **report.as_dict()}
        output_file(args.json).write_text(json.dumps(finite_json(data), indent=1,
                                                     allow_nan=False))
    if args.plot:
        from threat_planner.cli.flight_figure import plot_flight
        ratio = _ratio(report)
        plot_flight(output_file(args.plot), scenario, events, report,
                    title=f'{scenario.name}: flown J={report.flown.J:.1f}'
                          + ('' if ratio is None else f', {ratio:.3f} x hindsight'))
    return 0


def _ratio(report) -> float | None:
    best = report.hindsight
    if best is None or not (math.isfinite(best.J) and best.J > 0):
        return None
    return report.flown.J / best.J


def _replan_line(r: dict) -> str:
    head = f"  replan t={r['t']:.2f} s ({r.get('reason', '?')}): "
    if not r.get('ok', True):
        return head + f"FAILED, the last plan kept ({r.get('error', '')})"
    if r.get('note'):
        return head + r['note']
    rounds = r.get('rounds', 1)
    text = (f"{r['latency_ms']:.1f} ms, {rounds} round{'s' if rounds != 1 else ''}, "
            f"J planned {r['J_planned']:.3f}")
    if 'entry_turn_deg' in r:
        text += (f", entry turn {r['entry_turn_deg']:.1f} deg "
                 f"({'feasible' if r.get('entry_feasible') else 'NOT feasible'})")
    return head + text


def flight_lines(scenario: Scenario, cfg: PlannerConfig, events: list, report) -> list[str]:
    """Return the summary ``fly`` prints: replans, costs, jumps, goal, flown limits."""
    flown, best = report.flown, report.hindsight
    t_end = float(report.times[-1]) if len(report.times) else 0.0
    lines = [f'{scenario.name}: flew {t_end:.2f} s at {report.speed_mps:g} m/s '
             f'(commit {cfg.commit_s:g} s), {len(events)} events, {len(report.replans)} '
             f'plans']
    lines += [_replan_line(r) for r in report.replans]
    later = [r['latency_ms'] for r in report.replans[1:]
             if r.get('ok', True) and r.get('latency_ms') and not r.get('note')]
    if later:
        lines.append(f'  replan latency: median {float(np.median(later)):.1f} ms, max '
                     f'{max(later):.1f} ms over {len(later)}')
    ratio = _ratio(report)
    lines.append(f'  J_flown={flown.J:.3f} (J_L={flown.J_L:.3f} J_R={flown.J_R:.3f})'
                 + ('' if best is None else f', J_hindsight={best.J:.3f}')
                 + ('' if ratio is None else f', ratio {ratio:.4f}'))
    miss = report.goal_miss_m
    lines.append(f'  max_jump_m={report.max_jump_m:.3f}, max_tracking_m='
                 f'{report.max_tracking_m:.3f}, reached_goal={report.reached_goal}'
                 + (f' (miss {miss:.3f} m)' if math.isfinite(miss) else ''))
    lim = report.limits

    def num(key: str, unit: str) -> str:
        v = lim.get(key)
        return 'none' if v is None or not math.isfinite(v) else f'{v:.2f} {unit}'
    lines.append(f"  flown limits: climb {num('climb_deg', 'deg')}, dive "
                 f"{num('dive_deg', 'deg')}, turn radius {num('min_turn_radius_m', 'm')}"
                 f"; feasible={lim.get('feasible')}"
                 + (f" (over: {lim['violations']})" if lim.get('violations') else ''))
    for e in report.lethal:
        lines.append(f"  inside the lethal sphere of threat #{e['index']} (appeared t="
                     f"{e['appeared_t']:g} s) from t={e['first_t']:.2f} to "
                     f"{e['last_t']:.2f} s")
    return lines


@dataclass(frozen=True)
class HeadedPlan:
    """A plan brought onto the start heading: the result, its summary line and JSON keys."""

    result: PlanResult
    line: str
    fields: dict


def enter_plan(heading: NDArray, scenario: Scenario, cfg: PlannerConfig,
               result: PlanResult) -> HeadedPlan:
    """Bring `result`'s path onto `heading` and cost it exactly.

    The path leaves the start along the heading (:func:`.entry.enter`, the limits of
    `cfg`); its J is the closed form of :mod:`threat_planner.core.cost.closed_form` (the
    masked one where the terrain hides the UAV), its limits, angles and clearances
    checked again. ``entry_feasible``: it leaves along the heading within the limits,
    inside the box (when confined) and outside every zone.
    """
    from threat_planner.core.cost.closed_form import path_cost
    from threat_planner.core.flight.entry import enter
    from threat_planner.core.optimise.limits import check_limits, FlightLimits
    from threat_planner.core.optimise.smoothing import check_angles
    box, air = scenario.box, scenario.airspace
    limits = FlightLimits.of(cfg)
    entry = enter(result.path, heading, box if cfg.confine_to_box else None, limits)
    pts = entry.points
    if air.masking:
        from threat_planner.core.cost.masking import masked_cost
        cost = masked_cost(pts, scenario.threats, cfg.w, air)
    else:
        cost = path_cost(pts, scenario.threats.positions, scenario.threats.intensities, cfg.w)
    check = check_limits(pts, limits, float(box.lo[2]))
    inside = not cfg.confine_to_box or bool(np.all(
        (pts >= box.lo - 1e-9) & (pts <= box.hi + 1e-9)))
    clear = not air or not air.violations(pts)
    feasible = bool(entry.feasible and inside and clear)
    headed = replace(result, path=pts, cost=cost, limit_check=check,
                     angles=check_angles(pts, cfg.max_pitch_deg, cfg.max_turn_deg),
                     clearance=air.clearance(pts) if air else result.clearance)
    yaw = math.degrees(math.atan2(heading[1], heading[0]))
    pitch = math.degrees(math.asin(float(np.clip(heading[2], -1.0, 1.0))))
    why = [] if feasible else [w for w, bad in (
        ('limits', not entry.feasible), ('leaves the box', not inside),
        ('enters a zone', not clear)) if bad]
    line = (f'  start heading: yaw {yaw:.1f} deg, pitch {pitch:.1f} deg; first turn '
            f'{entry.turn_deg:.1f} deg, {entry.changed} vertices moved, feasible={feasible}'
            + (f" ({', '.join(why)})" if why else '')
            + f'; J {result.cost.J:.3f} as planned')
    fields = {'start_heading': heading.tolist(), 'entry_turn_deg': entry.turn_deg,
              'entry_feasible': feasible, 'entry_vertices_moved': entry.changed,
              'planned_cost': result.cost.as_dict()}
    return HeadedPlan(headed, line, fields)


def refuse_heading_with(args: argparse.Namespace) -> None:
    """Refuse ``plan --start-heading`` beside ``--robust`` or ``--record`` (one line)."""
    for flag, value in (('--robust', getattr(args, 'robust', None)),
                        ('--record', getattr(args, 'record', None))):
        if value is not None and value is not False:
            raise InputError(f'start_heading: not with {flag} (it would describe the path '
                             'before the heading)')
