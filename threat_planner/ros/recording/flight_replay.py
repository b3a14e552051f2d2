"""Replay a flight bag (``fly --record``): fly it again and compare, ``threat-planner replay``.

:func:`replay_flight` reads ``/flight_setup`` (:mod:`.flight_record`), flies the recorded
scenario through the recorded events with the recorded settings
(:func:`threat_planner.flight.fly.fly`, which replans exactly as the node does) and
compares the new flight with the recorded one:

* every plan, in order: its outcome (planned, failed, arriving), its time, the largest
  distance between its ``/path`` points and the recorded ones [m], and its ``replan_J``
  (relative);
* ``J_flown`` of ``/flight_result`` (relative) and ``reached_goal``.

The flight is deterministic, so a bag replays to the last bit on the machine that made
it; the tolerance (default 1e-6 m and 1e-6 relative, as plan replay) absorbs what another
CPU or BLAS may change. A plan that moved changes the rest of the flight, so the first
difference is the one to read.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
import json
import math
from pathlib import Path
from typing import Dict, List, Mapping, Optional

import numpy as np
from numpy.typing import NDArray

from threat_planner.bag.reader import read_ros_messages
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import scenario_from_dict
from threat_planner.errors import InputError, RecordingError
from threat_planner.flight.events import parse_events
from threat_planner.ros.conversions import (path_from_msg, PLAN_STATUS_NAME, plan_info_values,
                                            stamp_to_ns)
from threat_planner.ros.recording.bagfile import level_name
from threat_planner.ros.recording.flight_record import (FLIGHT_FORMAT, RESULT_TOPIC,
                                                        SETUP_TOPIC)

__all__ = ['FlightPlanRow', 'FlightReplay', 'RecordedFlight', 'load_flight', 'replay_flight']


@dataclass
class RecordedPlan:
    """One recorded plan: its ``plan_info`` and the trajectory published with it."""

    level: str
    values: Dict[str, str]
    points: Optional[NDArray]

    @property
    def outcome(self) -> str:
        """``'planned'``, ``'failed'`` or ``'arriving'`` (published nothing)."""
        if self.level == 'ERROR':
            return 'failed'
        return 'planned' if 'path_points' in self.values else 'arriving'


@dataclass
class RecordedFlight:
    """A flight bag read back: its setup, plans and result."""

    path: Path
    setup: dict
    plans: List[RecordedPlan]
    result: dict


def _json(path: Path, topic: str, text: str) -> dict:
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise RecordingError(f'{path}: {topic} is not JSON ({exc})') from None
    if not isinstance(data, dict):
        raise RecordingError(f'{path}: {topic}: expected a JSON object')
    return data


def load_flight(path, *, tolerant: bool = False) -> RecordedFlight:
    """Read a flight bag's setup, plans (with their paths) and result.

    Raises
    ------
    RecordingError
        One line naming the file: not readable (:func:`read_ros_messages`), no or a bad
        ``/flight_setup``, an unknown format, or a plan whose path is missing.

    """
    path = Path(path)
    setup, result = None, None
    infos, paths = [], {}
    for m in read_ros_messages(path, tolerant=tolerant,
                               topics=[SETUP_TOPIC, RESULT_TOPIC, '/path', '/plan_info']):
        if m.topic == SETUP_TOPIC and setup is None:
            setup = _json(path, m.topic, m.msg.data)
        elif m.topic == RESULT_TOPIC:
            result = _json(path, m.topic, m.msg.data)
        elif m.topic == '/path':
            paths[stamp_to_ns(m.msg.header.stamp)] = path_from_msg(m.msg)
        else:
            infos.append(m.msg)
    if setup is None:
        raise RecordingError(f'{path}: no {SETUP_TOPIC}: not a flight recording')
    if result is None:
        raise RecordingError(f'{path}: no {RESULT_TOPIC}: the flight did not finish '
                             'recording')
    if setup.get('format') != FLIGHT_FORMAT:
        raise RecordingError(f"{path}: {SETUP_TOPIC}.format: expected {FLIGHT_FORMAT!r}, "
                             f"got {setup.get('format')!r}")
    plans = []
    for msg in infos:
        try:
            values = plan_info_values(msg)
        except InputError as exc:
            raise RecordingError(f'{path}: /plan_info: {exc}') from None
        status = next(d for d in msg.status if d.name == PLAN_STATUS_NAME)
        plan = RecordedPlan(level_name(status.level), values, None)
        if plan.outcome == 'planned':
            t0 = int(values.get('t0_ns', -1))
            if t0 not in paths:
                raise RecordingError(f'{path}: /plan_info #{len(plans) + 1}: no /path '
                                     f'stamped t0_ns={t0}')
            plan.points = paths[t0]
        plans.append(plan)
    return RecordedFlight(path, setup, plans, result)


@dataclass
class FlightPlanRow:
    """The comparison of one plan of the flight."""

    index: int
    t: float
    reason: str
    recorded: str
    replayed: str = '-'
    max_dp: Optional[float] = None
    j_rel: Optional[float] = None
    ok: bool = True
    note: str = ''

    def line(self) -> str:
        """One line: the plan, its differences and whether it matches."""
        num = (lambda v: '-' if v is None else f'{v:.1e}')
        return (f'  plan {self.index} t={self.t:.2f} s ({self.reason}): {self.recorded} -> '
                f'{self.replayed}, max dp {num(self.max_dp)} m, replan_J rel '
                f'{num(self.j_rel)}: ' + ('ok' if self.ok else f'DIFFERS: {self.note}'))


@dataclass
class FlightReplay:
    """Result of :func:`replay_flight`."""

    flight: RecordedFlight
    tolerance: float
    overrides: Dict[str, object]
    rows: List[FlightPlanRow]
    j_flown: tuple = (None, None)
    reached_goal: tuple = (None, None)
    notes: List[str] = field(default_factory=list)

    @property
    def j_rel(self) -> Optional[float]:
        """Relative difference of J_flown (None if the bag has none)."""
        old, new = self.j_flown
        return None if old is None else abs(new - old) / max(abs(old), 1e-12)

    @property
    def ok(self) -> bool:
        """Whether every plan, J_flown and reached_goal match within the tolerance."""
        return all(r.ok for r in self.rows) and not self.notes

    def lines(self) -> List[str]:
        """Return the report: one line per plan, then the verdict."""
        return [r.line() for r in self.rows] + [self.summary()]

    def summary(self) -> str:
        """Return the verdict in one line."""
        old, new = self.j_flown
        rel = self.j_rel
        head = (f'{self.flight.path.name}: {len(self.rows)} plans, J_flown '
                + ('-' if old is None else f'{old:.9g}') + f' -> {new:.9g}'
                + ('' if rel is None else f' (relative {rel:.1e})')
                + f', reached_goal {self.reached_goal[0]} -> {self.reached_goal[1]}')
        if self.ok:
            return f'{head}; flight replayed, all within tolerance {self.tolerance:g}'
        first = next((r for r in self.rows if not r.ok), None)
        what = (f'plan {first.index} at t={first.t:.2f} s: {first.note}' if first is not None
                else '; '.join(self.notes))
        return f'{head}; REGRESSION (tolerance {self.tolerance:g}), first difference: {what}'

    def markdown(self) -> str:
        """Return the report as Markdown."""
        over = ', '.join(f'{k}={v!r}' for k, v in self.overrides.items()) or 'none'
        return '\n'.join([f'# Replay of the flight {self.flight.path.name}', '',
                          f'- recording: `{self.flight.path}`', f'- overrides: {over}',
                          f'- tolerance: {self.tolerance:g} (path points [m], relative J)',
                          '', *[f'-{r.line()[1:]}' for r in self.rows], '', self.summary(),
                          ''])


class _Collector:
    """fly()'s observer: keeps each plan and its trajectory."""

    def __init__(self) -> None:
        self.plans: List[tuple] = []

    def on_replan(self, record: dict, points, times) -> None:
        self.plans.append((record, points))

    def on_start(self, position, heading) -> None:
        pass

    def on_event(self, t, event) -> None:
        pass

    def on_step(self, t, position, heading) -> None:
        pass


def _outcome(record: dict, points) -> str:
    if points is not None:
        return 'planned'
    return 'arriving' if record.get('ok', True) else 'failed'


def _compare(row: FlightPlanRow, rec: RecordedPlan, record: dict, points,
             tol: float) -> None:
    notes = []
    if row.recorded != row.replayed:
        notes.append(f'{row.recorded} -> {row.replayed}')
    t_rec = float(rec.values.get('flight_t_s', 'nan'))
    if not abs(t_rec - float(record['t'])) <= 1e-9:
        notes.append(f"at t={record['t']:.6g} s, recorded {t_rec:.6g} s")
    if rec.points is not None and points is not None:
        if rec.points.shape != points.shape:
            notes.append(f'path has {len(points)} points, recorded {len(rec.points)}')
        else:
            row.max_dp = float(np.max(np.linalg.norm(rec.points - points, axis=1)))
            if not row.max_dp <= tol:
                notes.append(f'path points moved up to {row.max_dp:.3g} m')
        if 'replan_J' in rec.values and record.get('J_planned') is not None:
            old, new = float(rec.values['replan_J']), float(record['J_planned'])
            row.j_rel = abs(new - old) / max(abs(old), 1e-12)
            if not row.j_rel <= tol:
                notes.append(f'replan_J {old:.9g} -> {new:.9g} (relative {row.j_rel:.2e})')
    row.ok = not notes
    row.note = '; '.join(notes)


def _config(setup: dict, overrides: Mapping[str, object]) -> PlannerConfig:
    recorded = setup.get('config')
    known = {f.name for f in fields(PlannerConfig)}
    if not isinstance(recorded, dict) or set(recorded) - known:
        extra = sorted(set(recorded) - known) if isinstance(recorded, dict) else []
        raise RecordingError(f'{SETUP_TOPIC}.config: ' + (
            f'unknown setting {extra[0]!r}' if extra else 'expected a mapping'))
    try:
        return replace(PlannerConfig(**recorded), **overrides).validated()
    except TypeError as exc:
        raise InputError(f'overrides: {exc}') from None


def replay_flight(path, *, tolerance: float = 1e-6,
                  overrides: Optional[Mapping[str, object]] = None,
                  tolerant: bool = False) -> FlightReplay:
    """Fly a flight bag's flight again and compare it with the recorded one.

    Parameters
    ----------
    path : str or os.PathLike
        A flight bag (``threat-planner fly --record``).
    tolerance : float
        Largest path point distance [m] and relative J difference accepted.
    overrides : Mapping[str, object], optional
        PlannerConfig fields to use instead of the recorded ones (``speed_mps`` and
        ``commit_s`` also set the flight's speed and commit).
    tolerant : bool
        Read a bag cut off by a crash up to its last complete chunk.

    Returns
    -------
    FlightReplay

    Raises
    ------
    RecordingError
        A bad bag (:func:`load_flight`), naming the file or field.
    InputError, PlanningError
        A bad override or tolerance; a recorded scenario or event that no longer loads.

    """
    from threat_planner.flight.fly import fly
    if not (math.isfinite(tolerance) and tolerance >= 0.0):
        raise InputError(f'tolerance: must be finite and >= 0, got {tolerance!r}')
    flight = load_flight(path, tolerant=tolerant)
    setup = flight.setup
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    cfg = _config(setup, overrides)
    scenario = scenario_from_dict(setup.get('scenario'), f'{flight.path}: {SETUP_TOPIC}')
    events = parse_events({'events': setup.get('events') or []})
    heading = setup.get('heading')
    collector = _Collector()
    report = fly(scenario, events, cfg,
                 cfg.speed_mps if 'speed_mps' in overrides else float(setup['speed']),
                 commit_s=cfg.commit_s if 'commit_s' in overrides else float(
                     setup['commit_s']),
                 dt=float(setup['dt']),
                 heading=None if heading is None else np.asarray(heading, float),
                 max_time_s=setup.get('max_time_s'), hindsight=False, observer=collector)
    rows = []
    for i in range(max(len(flight.plans), len(collector.plans))):
        rec = flight.plans[i] if i < len(flight.plans) else None
        new = collector.plans[i] if i < len(collector.plans) else None
        if rec is None or new is None:
            t = float(new[0]['t']) if new else float(rec.values.get('flight_t_s', 'nan'))
            reason = new[0].get('reason', '') if new else rec.values.get('plan_reason', '')
            rows.append(FlightPlanRow(i + 1, t, reason, rec.outcome if rec else '-',
                                      _outcome(*new) if new else '-', ok=False,
                                      note='not in the recording' if rec is None
                                      else 'not made by the replay'))
            continue
        record, points = new
        row = FlightPlanRow(i + 1, float(record['t']), str(record.get('reason', '')),
                            rec.outcome, _outcome(record, points))
        _compare(row, rec, record, points, tolerance)
        rows.append(row)
    out = FlightReplay(flight, tolerance, overrides, rows)
    result = flight.result
    old = result.get('J_flown')
    out.j_flown = (None if old is None else float(old), report.flown.J)
    out.reached_goal = (result.get('reached_goal'), report.reached_goal)
    if old is None or not out.j_rel <= tolerance:
        out.notes.append(f'J_flown {old} -> {report.flown.J:.9g}')
    if out.reached_goal[0] != out.reached_goal[1]:
        out.notes.append(f'reached_goal {out.reached_goal[0]} -> {out.reached_goal[1]}')
    return out
