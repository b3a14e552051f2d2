"""The figure of ``threat-planner fly --plot``: a top view and a side view of a flight.

Threats are drawn where they were at the start of each of their pieces (size by F), a
moving one with its track over the flight, a pop-up with a cross and a removed one with
an x where it left; lethal radii as circles; the flown path, the plan made with hindsight
(when the report carries its points, ``hindsight_path``), the vehicle's position at each
replan (numbered, a failed one hollow), the start and the goals.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use('Agg')  # files only: no display is needed or wanted

import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from threat_planner.core.inputs.scenario import Scenario  # noqa: E402
from threat_planner.flight.events import apply_event  # noqa: E402
from threat_planner.flight.fly import scenario_timeline  # noqa: E402

__all__ = ['VIEWS', 'plot_flight']

#: The two views: (title, horizontal axis, vertical axis) as coordinate indices.
VIEWS = (('top view', 0, 1), ('side view', 0, 2))


def _at(times: NDArray, path: NDArray, t: float) -> NDArray:
    """Return the flown position at time `t` (linear between the flown points)."""
    return np.array([np.interp(t, times, path[:, c]) for c in range(3)])


def _draw_threats(ax, scenario: Scenario, events: list, t_end: float, i: int, j: int,
                  first_view: bool) -> None:
    truth = scenario_timeline(scenario)
    zones: list = []
    for e in events:
        apply_event(e, truth, zones)
    ids, f, origin, vel, on, off, lethal = truth.pieces()
    if not len(ids):
        return
    f_max = float(f.max())
    seen: set[int] = set()
    n0 = len(scenario.threats)
    last = {int(ids[k]): k for k in np.argsort(on, kind='stable')}   # each threat's last piece
    labels = {'track': 'threat track', 'popup': 'pop-up', 'moved': 'moved to',
              'removed': 'removed'} if first_view else {}
    for k in np.argsort(on, kind='stable'):
        if on[k] > t_end:
            continue
        end = min(off[k], t_end)
        p0, p1 = origin[k], origin[k] + vel[k] * (end - on[k])
        if np.linalg.norm(p1 - p0) > 1e-9:
            ax.plot([p0[i], p1[i]], [p0[j], p1[j]], color='tab:orange', lw=0.8, ls='--',
                    alpha=0.8, label=labels.pop('track', None))
        popup = ids[k] >= n0
        if int(ids[k]) not in seen:
            ax.scatter(p0[i], p0[j], s=20 + 220 * f[k] / f_max, c='tab:red' if popup
                       else 'tab:orange', marker='X' if popup else 'o', alpha=0.6,
                       edgecolors='k', linewidths=0.3, zorder=3,
                       label=labels.pop('popup', None) if popup else None)
        else:   # a move: where it went on from
            ax.scatter(p0[i], p0[j], s=18, marker='D', color='tab:orange', edgecolors='k',
                       linewidths=0.3, zorder=3, label=labels.pop('moved', None))
        seen.add(int(ids[k]))
        if off[k] <= t_end and last[int(ids[k])] == k:   # it left (was removed)
            ax.scatter(p1[i], p1[j], marker='x', s=30, color='0.3', zorder=3,
                       label=labels.pop('removed', None))
        if np.isfinite(lethal[k]):
            for p in (p0, p1) if np.linalg.norm(p1 - p0) > 1e-9 else (p0,):
                ax.add_patch(Circle((p[i], p[j]), lethal[k], fill=False, color='tab:red',
                                    lw=1.0))
    for z in zones:
        if getattr(z, 'kind', '') == 'sphere':
            ax.add_patch(Circle((z.center[i], z.center[j]), z.radius, fill=False,
                                color='tab:purple', lw=1.0, ls=':'))


def plot_flight(path_png: str | Path, scenario: Scenario, events: list, report,
                title: str = '') -> Path:
    """Draw a flight's top view (x, y) and side view (x, z) into a PNG.

    Parameters
    ----------
    path_png : str or Path
        Output file.
    scenario : Scenario
        The scenario flown (box, start, goal, threats at t = 0).
    events : list of Event
        The events flown through (pop-ups, moves, removals, zones, goals).
    report : FlightReport
        The flight (:func:`threat_planner.flight.fly.fly`).
    title : str
        Figure title.

    Returns
    -------
    Path
        The written file.

    """
    times, flown = np.asarray(report.times, float), np.asarray(report.path, float)
    t_end = float(times[-1]) if len(times) else 0.0
    hindsight = getattr(report, 'hindsight_path', None)
    hindsight = None if hindsight is None else np.asarray(hindsight, float).reshape(-1, 3)
    goals = [np.asarray(e.values['goal'], float) for e in events if e.kind == 'goal']
    fig, axes = plt.subplots(1, 2, figsize=(13, 6.2))
    for n, (ax, (name, i, j)) in enumerate(zip(axes, VIEWS)):
        lo, hi = scenario.box.lo, scenario.box.hi
        ax.add_patch(Rectangle((lo[i], lo[j]), hi[i] - lo[i], hi[j] - lo[j], fill=False,
                               color='0.6', lw=0.8))
        _draw_threats(ax, scenario, events, t_end, i, j, n == 0)
        if hindsight is not None:
            h = hindsight
            ax.plot(h[:, i], h[:, j], color='tab:green', lw=1.2, ls='--',
                    label='plan with hindsight')
        ax.plot(flown[:, i], flown[:, j], color='k', lw=1.6, label='flown')
        for m, r in enumerate(report.replans[1:], start=1):
            p = _at(times, flown, float(r['t']))
            ok = r.get('ok', True)
            ax.scatter(p[i], p[j], s=36, zorder=4, facecolors='tab:blue' if ok else 'none',
                       edgecolors='tab:blue', label='replan' if m == 1 else None)
            ax.annotate(str(m), (p[i], p[j]), textcoords='offset points', xytext=(4, 4),
                        fontsize=7, color='tab:blue')
        ax.scatter(scenario.start[i], scenario.start[j], marker='^', s=70, color='green',
                   zorder=5, label='start')
        ax.scatter(scenario.goal[i], scenario.goal[j], marker='*', s=110, color='purple',
                   zorder=5, label='goal')
        for g in goals:
            ax.scatter(g[i], g[j], marker='*', s=110, facecolors='none',
                       edgecolors='purple', zorder=5, label='new goal' if g is goals[0]
                       else None)
        shown = np.vstack([lo, hi, flown] + ([] if hindsight is None else [hindsight]))
        a, b = shown.min(axis=0), shown.max(axis=0)
        pad = 0.05 * float(np.max(b - a) or 1.0)
        ax.set_xlim(a[i] - pad, b[i] + pad)
        ax.set_ylim(a[j] - pad, b[j] + pad)
        ax.set_aspect('equal', adjustable='box')
        ax.set_xlabel('xyz'[i] + ' [m]')
        ax.set_ylabel('xyz'[j] + ' [m]')
        ax.set_title(name, fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(loc='best', fontsize=7)
    fig.suptitle(title, fontsize=11)
    out = Path(path_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, bbox_inches='tight')
    plt.close(fig)
    return out
