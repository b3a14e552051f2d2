"""Airspace in the 3-D figures: zones as wireframes, the terrain surface, masked path parts."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.world.zones import BoxZone, Cylinder, Sphere

#: Samples per segment when shading the parts of the path no radar sees.
SHADE_SAMPLES = 16


def _zone_lines(zone) -> list[NDArray]:
    """Polylines (k, 3) outlining a zone."""
    t = np.linspace(0, 2 * np.pi, 41)
    if isinstance(zone, Sphere):
        c, r = zone.center, zone.radius
        out = []
        for k in range(3):
            ring = np.zeros((len(t), 3))
            ax = [i for i in range(3) if i != k]
            ring[:, ax[0]], ring[:, ax[1]] = r * np.cos(t), r * np.sin(t)
            out.append(c + ring)
        return out
    if isinstance(zone, Cylinder):
        ring = zone.center + zone.radius * np.stack([np.cos(t), np.sin(t)], 1)
        rings = [np.column_stack([ring, np.full(len(t), z)]) for z in (zone.z_min, zone.z_max)]
        posts = [np.array([[*ring[i], zone.z_min], [*ring[i], zone.z_max]])
                 for i in range(0, 40, 10)]
        return rings + posts
    if isinstance(zone, BoxZone):
        poly = np.array([[zone.lo[0], zone.lo[1]], [zone.hi[0], zone.lo[1]],
                         [zone.hi[0], zone.hi[1]], [zone.lo[0], zone.hi[1]]])
        z0, z1 = zone.lo[2], zone.hi[2]
    else:
        poly, z0, z1 = zone.polygon, zone.z_min, zone.z_max
    closed = np.vstack([poly, poly[:1]])
    out = [np.column_stack([closed, np.full(len(closed), z)]) for z in (z0, z1)]
    out += [np.array([[*v, z0], [*v, z1]]) for v in poly]
    return out


def draw_airspace(ax, airspace, box, threats, path: NDArray | None) -> None:
    """Draw zones, terrain and the final path (masked parts grey) on a 3-D axis."""
    label = 'no-fly zones'
    for zone in airspace.zones:
        for line in _zone_lines(zone):
            ax.plot(*np.clip(line, box.lo, box.hi).T, color='tab:orange', linewidth=0.9,
                    label=label)
            label = None
    ter = airspace.terrain
    if ter is not None:
        x = np.linspace(box.lo[0], box.hi[0], 40)
        y = np.linspace(box.lo[1], box.hi[1], 40)
        xx, yy = np.meshgrid(x, y)
        zz = ter.height(np.stack([xx, yy], -1))
        ax.plot_surface(xx, yy, zz, cmap='terrain', alpha=0.35, linewidth=0)
    if path is None:
        return
    if not airspace.masking or len(threats) == 0:
        ax.plot(*path.T, color='k', linewidth=2.2, label='final path')
        return
    f = np.linspace(0, 1, SHADE_SAMPLES + 1)
    pts = (path[:-1, None] + f[None, :, None] * np.diff(path, axis=0)[:, None]).reshape(-1, 3)
    seen = np.zeros(len(pts), bool)
    for p in threats.positions:
        seen |= ter.visible(p, pts)
    for flag, colour, name in ((True, 'k', 'final path (seen)'),
                               (False, '0.6', 'final path (masked)')):
        xyz = np.where((seen == flag)[:, None], pts, np.nan)
        ax.plot(*xyz.T, color=colour, linewidth=2.2, label=name)
