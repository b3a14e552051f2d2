"""The detection outputs of ``threat-planner plan`` (issue 43): its print line and figure.

* :func:`detection_line`: one line of the plan's summary, P_detect, H and the largest
  threat's share under the radar model it is reported under.
* :func:`plot_detection` (``--detection-plot FILE.png``): left, P_d per scan of each threat
  along the path against the distance flown (the threats with more than
  :data:`MATTERS` of H in colour, the rest grey); right, the path in plan view coloured by
  the local hazard rate sum_i P_d,i / (v T) [1/m], the threats as dots of area ~ F.

matplotlib is imported only to draw, so the print line costs no import.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from threat_planner.core.detection.hazard import profile
from threat_planner.core.detection.model import DetectionModel

__all__ = ['MATTERS', 'add_detection_plot_option', 'detection_line', 'dot_sizes', 'model_text',
           'plot_detection', 'report_model']

#: Share of H above which a threat is drawn in colour in the P_d panel.
MATTERS = 0.01


def add_detection_plot_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--detection-plot FILE.png`` to a command's parser."""
    parser.add_argument('--detection-plot', metavar='FILE.png',
                        help='write the detection figure (PNG) here: P_d per scan of each '
                             'threat along the path, and the path in plan view coloured by '
                             'the hazard rate')


def report_model(result) -> DetectionModel:
    """Return the radar model a plan's detection is reported under."""
    return result.detection_model or DetectionModel(speed_mps=result.speed_mps)


def model_text(model: DetectionModel) -> str:
    """Return the model in words: ``swerling 1, rcs constant 1, p_fa 1e-06, T 1 s, v 20 m/s``."""
    rcs = ' '.join([model.rcs_kind, *(f'{v:g}' for v in model.rcs_values)])
    return (f'swerling {model.swerling}, rcs {rcs}, p_fa {model.p_fa:g}, '
            f'T {model.scan_period_s:g} s, v {model.speed_mps:g} m/s')


def detection_line(result) -> str:
    """Return the plan summary's detection line: P_detect, H, the largest share, the model.

    ``  detection: P_detect=0.0001632 H=0.0001633 (largest: threat 4, 35.2 % of H)
    swerling 1, rcs constant 1, p_fa 1e-06, T 1 s, v 20 m/s`` (one line), with
    ``; status: ...`` at the end when a detection plan's bound has one.
    """
    report = result.detection
    per = np.asarray(report.per_threat, float)
    if len(per) and report.hazard > 0:
        i = int(np.argmax(per))
        share = f'(largest: threat {i}, {100.0 * per[i] / report.hazard:.1f} % of H)'
    else:
        share = '(no threat seen)'
    status = f'; status: {result.detection_status}' if result.detection_status else ''
    return (f'  detection: P_detect={report.p_detect:.4g} H={report.hazard:.4g} {share} '
            f'{model_text(report_model(result))}{status}')


def dot_sizes(intensities, smallest: float = 8.0, largest: float = 160.0):
    """Marker areas [pt^2] of the threats' dots, in proportion to F (the largest F: `largest`)."""
    f = np.abs(np.asarray(intensities, float).ravel())
    top = float(f.max()) if len(f) else 0.0
    if not (top > 0.0 and np.isfinite(top)):
        return np.full(len(f), smallest)
    return np.maximum(largest * f / top, smallest)


def plot_detection(path_png: str | Path, result, title: str = '') -> Path:
    """Draw a plan's detection figure (see the module) and write it as PNG.

    Args:
        path_png: Output file.
        result: A ``PlanResult`` (its path, threats and radar model).
        title: Figure title.

    Returns:
        The written file's path.
    """
    # matplotlib only when drawing: the plan's print line needs none of it.
    import matplotlib
    matplotlib.use('Agg')  # files only: no display is needed or wanted
    from matplotlib.collections import LineCollection
    from matplotlib.colors import LogNorm
    import matplotlib.pyplot as plt

    threats = result.problem[0]
    model = report_model(result)
    points = np.asarray(result.path, float)
    report = result.detection
    s, p_d = profile(points, threats.positions, threats.intensities, model)
    per = np.asarray(report.per_threat, float)
    share = per / report.hazard if report.hazard > 0 else np.zeros_like(per)
    matters = np.flatnonzero(share > MATTERS)
    matters = matters[np.argsort(-share[matters], kind='stable')]

    fig, (ax_p, ax_m) = plt.subplots(1, 2, figsize=(13, 5.2))
    floor = model.p_fa
    for i in np.setdiff1d(np.arange(len(per)), matters):
        ax_p.plot(s, np.maximum(p_d[i], floor), color='0.75', linewidth=0.6)
    colours = plt.get_cmap('tab10')
    for n, i in enumerate(matters):
        ax_p.plot(s, np.maximum(p_d[i], floor), color=colours(n % 10), linewidth=1.4,
                  label=f'threat {i} ({100 * share[i]:.1f} % of H)' if n < 10 else None)
    ax_p.set_yscale('log')
    ax_p.set_xlabel('distance along path [m]')
    ax_p.set_ylabel('P_d per scan')
    masked = ' (terrain masking not drawn)' if result.masking is not None else ''
    ax_p.set_title(f'P_d per scan; colour: > {100 * MATTERS:g} % of H{masked}', fontsize=9)
    if len(matters):
        ax_p.legend(fontsize=7, loc='upper right')
    ax_p.grid(True, which='both', alpha=0.3)

    # Hazard rate at each sample: sum_i P_d,i / (v T) [1/m], drawn between samples.
    rate = p_d.sum(axis=0) / model.metres_per_scan
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    xy = np.column_stack([np.interp(s, cum, points[:, 0]), np.interp(s, cum, points[:, 1])])
    xy = np.vstack([points[:1, :2], xy, points[-1:, :2]])
    rate_at = np.concatenate([rate[:1], rate, rate[-1:]])
    segments = np.stack([xy[:-1], xy[1:]], axis=1)
    seg_rate = np.maximum(0.5 * (rate_at[:-1] + rate_at[1:]), 1e-300)
    lo, hi = float(seg_rate.min()), float(seg_rate.max())
    norm = LogNorm(vmin=lo, vmax=hi if hi > lo else lo * 10.0)
    lines = LineCollection(segments, cmap='inferno', norm=norm, linewidths=3.0)
    lines.set_array(seg_rate)
    ax_m.add_collection(lines)
    fig.colorbar(lines, ax=ax_m, label='hazard rate sum_i P_d,i / (vT) [1/m]')
    if len(threats):
        pos = threats.positions
        size = dot_sizes(threats.intensities)
        ax_m.scatter(pos[:, 0], pos[:, 1], s=size, color='0.55', edgecolors='k',
                     linewidths=0.3, label='threats (dot area ~ F)', zorder=3)
        if len(matters):
            ax_m.scatter(pos[matters, 0], pos[matters, 1], s=size[matters], color='tab:red',
                         edgecolors='k', linewidths=0.4, zorder=4,
                         label=f'> {100 * MATTERS:g} % of H')
            for i in matters[:10]:
                ax_m.annotate(str(i), pos[i, :2], fontsize=7, xytext=(3, 3),
                              textcoords='offset points')
    ax_m.scatter(*points[0, :2], marker='^', s=60, color='green', label='S', zorder=5)
    ax_m.scatter(*points[-1, :2], marker='*', s=90, color='purple', label='T', zorder=5)
    box = result.problem[3]
    ax_m.set_xlim(box.lo[0], box.hi[0])
    ax_m.set_ylim(box.lo[1], box.hi[1])
    ax_m.set_aspect('equal', adjustable='box')
    ax_m.set_xlabel('x [m]')
    ax_m.set_ylabel('y [m]')
    ax_m.set_title(f'P_detect={report.p_detect:.4g}, H={report.hazard:.4g}', fontsize=9)
    ax_m.legend(fontsize=7, loc='upper left')
    fig.suptitle((title + '\n' if title else '') + model_text(model), fontsize=10)
    out = Path(path_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches='tight')
    plt.close(fig)
    return out
