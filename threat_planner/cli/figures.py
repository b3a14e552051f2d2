"""3-D figures in the style of the paper's Figs. 8, 9 and 12-14 (matplotlib, PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use('Agg')  # files only: no display is needed or wanted

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from threat_planner.core.world.threats import Box, ThreatField  # noqa: E402


def plot_plan(path_png: str | Path, threats: ThreatField, box: Box, start: NDArray,
              goal: NDArray, network_nodes: NDArray | None = None,
              network_edges: NDArray | None = None, initial_path: NDArray | None = None,
              path: NDArray | None = None, title: str = '', airspace=None) -> Path:
    """Draw threats as spheres sized by intensity, the network, and the two paths.

    Args:
        path_png: Output file.
        threats: Threat field.
        box: Flight box (axis limits).
        start: Start point (3,) [m].
        goal: Goal point (3,) [m].
        network_nodes: Incentres (M, 3) [m], or None.
        network_edges: Node pairs (E, 2), or None.
        initial_path: Dijkstra path (m, 3) [m], or None.
        path: Final path (n, 3) [m], or None.
        title: Figure title.
        airspace: An ``airspace.Airspace`` to draw (zones, terrain, the path's masked
            parts in grey), or None.

    Returns:
        The written file's path.
    """
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection='3d')
    if len(threats):
        f = threats.intensities
        size = 30 + 400 * (f / f.max())
        ax.scatter(*threats.positions.T, s=size, c=f, cmap='autumn_r', alpha=0.55,
                   edgecolors='k', linewidths=0.3, label='threats (size ~ F)')
    if network_nodes is not None and network_edges is not None and len(network_edges):
        seg = network_nodes[network_edges]
        # One polyline with NaN breaks draws thousands of edges in a single artist.
        xyz = np.concatenate([seg, np.full((len(seg), 1, 3), np.nan)], axis=1).reshape(-1, 3)
        ax.plot(*xyz.T, color='tab:red', linestyle=':', linewidth=0.5, alpha=0.5,
                label='network')
        ax.scatter(*network_nodes.T, s=4, color='tab:red', alpha=0.5)
    if initial_path is not None:
        ax.plot(*initial_path.T, color='tab:blue', linewidth=1.2, label='initial (Dijkstra)')
    if airspace is not None:
        from threat_planner.cli.airspace_figures import draw_airspace
        draw_airspace(ax, airspace, box, threats, path)
    elif path is not None:
        ax.plot(*path.T, color='k', linewidth=2.2, label='final path')
    ax.scatter(*start, marker='^', s=60, color='green', label='S')
    ax.scatter(*goal, marker='*', s=90, color='purple', label='T')
    ax.set_xlim(box.lo[0], box.hi[0])
    ax.set_ylim(box.lo[1], box.hi[1])
    ax.set_zlim(box.lo[2], box.hi[2])
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_zlabel('z [m]')
    ax.set_title(title, fontsize=10)
    ax.legend(loc='upper left', fontsize=7)
    out = Path(path_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches='tight')
    plt.close(fig)
    return out
