"""An events file played in real time against a scenario: the picture as it is at time t.

The ``threat_publisher`` node (:mod:`threat_planner.ros.publisher`) plays one: at each
event's time after its start it applies the event (:func:`.events.apply_event`) to the
scenario's :class:`~threat_planner.core.flight.timeline.ThreatTimeline`
(:func:`.fly.scenario_timeline`) and publishes the threats where they are then.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.flight.timeline import Snapshot
from threat_planner.core.world.airspace import Zone
from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import InputError
from threat_planner.flight.events import apply_event, Event, load_events
from threat_planner.flight.fly import scenario_timeline

__all__ = ['Playback']


class Playback:
    """A scenario's threats, zones and goal changed by events at their times.

    Parameters
    ----------
    scenario : Scenario
        Threats (with their velocities and lethal radii), box and goal at t = 0.
    events : list of Event
        In time order (:func:`.events.parse_events`).

    Raises
    ------
    InputError
        An event that cannot apply (a move of a threat that does not exist) or a goal
        outside the scenario's bounds, naming the event's field; checked before any plays.

    """

    def __init__(self, scenario, events: list[Event]) -> None:
        box = scenario.box
        check, zones = scenario_timeline(scenario), []
        for e in events:
            goal = apply_event(e, check, zones)
            if goal is not None and not box.contains(goal):
                raise InputError(f'{e.label}: {goal.tolist()} is outside bounds '
                                 f'{box.lo.tolist()}..{box.hi.tolist()}')
        self.events = list(events)
        self.timeline = scenario_timeline(scenario)
        self.zones: list[Zone] = []
        self._next = 0

    @classmethod
    def from_file(cls, scenario, path: str | Path) -> 'Playback':
        """Load and check an events file (:func:`.events.load_events`) for `scenario`."""
        return cls(scenario, load_events(path))

    def due(self, t: float) -> list[tuple[Event, NDArray | None]]:
        """Apply the events due by time `t` [s]; return each with its new goal (or None)."""
        out = []
        while self._next < len(self.events) and self.events[self._next].t <= t + 1e-9:
            e = self.events[self._next]
            out.append((e, apply_event(e, self.timeline, self.zones)))
            self._next += 1
        return out

    @property
    def finished(self) -> bool:
        """Whether every event has been applied."""
        return self._next >= len(self.events)

    def picture(self, t: float) -> Snapshot:
        """Return the threats active at time `t` [s], where they are then, by index."""
        snap = self.timeline.snapshot(t)
        k = np.argsort(snap.ids, kind='stable')
        return Snapshot(ThreatField.from_arrays(snap.field.positions[k],
                                                snap.field.intensities[k]),
                        snap.velocities[k], snap.lethal[k], snap.ids[k])

    def moving(self, t: float) -> bool:
        """Whether a threat active at time `t` [s] has a velocity."""
        _, _, _, vel, _, _, _ = self.timeline.pieces()
        k = self.timeline.active(t)
        return bool(len(k) and np.any(vel[k] != 0.0))
