"""The report figure (PNG): coverage per pressure level, the path, marks and lesions revealed, the
summary numbers (no ROS; matplotlib Agg)."""
from __future__ import annotations

import os

import numpy as np

from .config import LEVELS


def save_figure(session, report: dict, path: str | os.PathLike) -> None:
    """Write the figure of ``session`` (an :class:`ExamSession`) and its ``report`` to ``path``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    g = session.grid
    tri = g.vertices[g.faces[g.faces_index]][:, :, 1:3] * 1e3    # (m, 3, 2) y, z [mm]
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.6))
    R = session.region_radius * 1e3
    for k, name in enumerate(LEVELS):
        ax = axes[k]
        col = np.where(g.covered[:, k], 1.0, 0.0)
        pc = PolyCollection(tri, array=col, cmap='RdYlGn', edgecolors='none')
        pc.set_clim(0, 1)
        ax.add_collection(pc)
        ax.set_title(f"{name} (depth >= {report['levels_mm'][name]:.0f} mm): "
                     f"{report['coverage_pct'][name]:.0f} %")
        _frame(ax, R)
    ax = axes[3]
    c = np.array(session.contacts, float).reshape(-1, 6)
    if len(c):
        ins = c[:, 5] > 0.5
        ax.plot(c[:, 2] * 1e3, c[:, 3] * 1e3, color='0.8', lw=0.5, label='probe path')
        sc = ax.scatter(c[ins, 2] * 1e3, c[ins, 3] * 1e3, c=c[ins, 4] * 1e3, s=1, cmap='viridis',
                        label='in contact (depth mm)')
        fig.colorbar(sc, ax=ax, fraction=0.04, label='depth [mm]')
    for les in report['lesions']:
        y, z = les['surface_mm'][1:]
        circ = plt.Circle((y, z), les['radius_mm'], fill=False,
                          color='tab:blue' if les['found'] else 'tab:red', lw=2)
        ax.add_patch(circ)
        ax.annotate(f"{les['name']}: {'found' if les['found'] else les['missed']}", (y, z),
                    xytext=(4, 12), textcoords='offset points', fontsize=8)
    for m in report['marks']:
        if m['surface_mm'] is None:
            continue
        ax.plot(m['surface_mm'][1], m['surface_mm'][2], marker='x', ms=10, mew=2,
                color={'hit': 'tab:blue', 'repeat': 'tab:cyan'}.get(m['result'], 'tab:red'))
    ax.set_title(f"path, marks (x), lesions (o): {report['pattern']}")
    _frame(ax, R)
    fig.suptitle(f"score {report['score']:.0f} ({report['verdict']}) | hits {report['hits']}, "
                 f"misses {report['misses']}, false marks {report['false_marks']} | "
                 f"{report['duration_s']:.0f} s, in contact {report['contact_s']:.0f} s, path "
                 f"{report['path_length_m']:.2f} m")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _frame(ax, R):
    ax.set_xlim(-R - 5, R + 5)
    ax.set_ylim(-R - 5, R + 5)
    ax.set_aspect('equal')
    ax.set_xlabel('y [mm]')
    ax.set_ylabel('z [mm]')
