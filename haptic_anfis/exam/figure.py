"""The report figure (PNG): where the skin was pressed and how deep, the path, the marks and the
lesions revealed (and a nodular case's normal lobules and ribs beside them), with the summary
numbers (no ROS; matplotlib Agg). Its colours are the picture
language every figure and the page share (:mod:`haptic_anfis.palette`): red is pressed deep,
bluish green found, reddish purple missed, black a false mark."""
from __future__ import annotations

import os

import numpy as np

from .. import palette
from .config import LEVELS

try:  # matplotlib: an optional dependency (the 'report' and 'fe' extras); PNG files, no display
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch
except ImportError:
    plt = None


def deepest_level(covered: np.ndarray) -> np.ndarray:
    """Per face, the deepest pressure level reached: 0 none, 1.. ``len(LEVELS)`` (``covered``:
    (faces, levels) bool, the coverage grid's)."""
    idx = np.arange(1, covered.shape[1] + 1)
    return np.max(np.where(covered, idx, 0), axis=1)


def save_figure(session, report: dict, path: str | os.PathLike) -> None:
    """Write the figure of ``session`` (an :class:`ExamSession`) and its ``report`` to ``path``."""
    if plt is None:
        raise ImportError('the report figure needs matplotlib (pip install matplotlib)')
    g = session.grid
    tri = g.vertices[g.faces[g.faces_index]][:, :, 1:3] * 1e3    # (m, 3, 2) y, z [mm]
    R = session.region_radius * 1e3
    fig, axes = plt.subplots(1, 2, figsize=(12, 6.4), layout='constrained')
    # -- where and how deep the skin was pressed
    ax = axes[0]
    colours = [palette.NOT_PRESSED] + [palette.LEVEL[n] for n in LEVELS]
    pc = PolyCollection(tri, array=deepest_level(np.asarray(g.covered, bool)),
                        cmap=ListedColormap(colours), edgecolors='none')
    pc.set_clim(-0.5, len(LEVELS) + 0.5)
    ax.add_collection(pc)
    for a in axes:   # the region to examine, outlined: what is left unpressed shows inside it
        a.add_patch(plt.Circle((0, 0), R, fill=False, ls='--', lw=1, color=palette.REGION,
                               zorder=0.5))
    cov = report['coverage_pct']
    handles = [Patch(fc=palette.NOT_PRESSED, ec=palette.REGION, lw=0.5,
                     label=palette.LEVEL_LABEL['none'])] + [
        Patch(color=palette.LEVEL[n], label=f"{n} (>= {report['levels_mm'][n]:.0f} mm): "
                                            f"{cov[n]:.0f} %") for n in LEVELS]
    ax.legend(handles=handles, title='deepest press (share of the region)', fontsize=8,
              title_fontsize=8, loc='upper center', bbox_to_anchor=(0.5, -0.12), ncol=2)
    ax.set_title('where the skin was pressed, and how deep')
    _frame(ax, R)
    # -- the path, its depth, the marks and the lesions
    ax = axes[1]
    c = np.array(session.contacts, float).reshape(-1, 6)
    if len(c):
        ins = c[:, 5] > 0.5
        ax.plot(c[:, 2] * 1e3, c[:, 3] * 1e3, color='0.75', lw=0.5, zorder=1)
        sc = ax.scatter(c[ins, 2] * 1e3, c[ins, 3] * 1e3, c=c[ins, 4] * 1e3, s=1, zorder=2,
                        cmap=palette.PRESSURE_CMAP, vmin=0)
        fig.colorbar(sc, ax=ax, fraction=0.04, label='press depth [mm]')
    for les in report['lesions']:
        y, z = les['surface_mm'][1:]
        state = ('found' if les['found'] else 'not palpable'
                 if les.get('palpable') is False else 'missed')
        ax.add_patch(plt.Circle((y, z), les['radius_mm'], fill=False, lw=2.5, zorder=3,
                                color=palette.FINDING[state]))
        ax.annotate(les['name'], (y, z + les['radius_mm']), xytext=(0, 3),
                    textcoords='offset points', ha='center', va='bottom', fontsize=8,
                    zorder=5, bbox={'boxstyle': 'round,pad=0.15', 'fc': 'white', 'ec': 'none',
                                    'alpha': 0.8})
    normal = _draw_normal(ax, report.get('normal') or [])
    for m in report['marks']:
        if m['surface_mm'] is None:
            continue
        ax.plot(m['surface_mm'][1], m['surface_mm'][2], marker='X', ms=11, mew=1, zorder=4,
                mec='white', color=palette.MARK.get(m['result'], palette.MARK['false']))
    ax.set_title(f"path ({report['pattern']}), marks and lesions")
    _frame(ax, R)
    ring = dict(marker='o', ls='none', ms=11, mfc='none', mew=2.5)
    cross = dict(marker='X', ls='none', ms=10, mec='white')
    handles = [Line2D([], [], color='0.75', lw=1, label='probe path'),
               Line2D([], [], color=palette.REGION, lw=1, ls='--', label='region to examine'),
               *(Line2D([], [], color=palette.FINDING[s], label=f'lesion {s}', **ring)
                 for s in palette.FINDING),
               *(Line2D([], [], color=palette.MARK[k], label=f'mark: {w}', **cross)
                 for k, w in (('hit', 'on a lesion'), ('repeat', 'again on one'),
                              ('false', 'false'))),
               *(Line2D([], [], color=palette.NORMAL[k], lw=1.5, ls=':', label=w)
                 for k, w in (('normal', 'normal lobule / rib'),
                              ('confounder', 'normal, stands out like a lump')) if k in normal)]
    ax.legend(handles=handles, fontsize=8, loc='upper center', bbox_to_anchor=(0.5, -0.12),
              ncol=3)
    fig.suptitle(f"score {report['score']:.0f} ({report['verdict']}): hits {report['hits']}, "
                 f"misses {report['misses']}, false marks {report['false_marks']}; "
                 f"{report['duration_s']:.0f} s, in contact {report['contact_s']:.0f} s, path "
                 f"{report['path_length_m']:.2f} m")
    # 'tight': the legends below the maps are part of the picture, never cut off
    fig.savefig(path, dpi=90, bbox_inches='tight', pad_inches=0.15)
    plt.close(fig)


def _draw_normal(ax, normal: list[dict]) -> set[str]:
    """A nodular case's normal lobules (dotted circles) and ribs under the region (dotted lines)
    from the report's ``normal`` entries, blue, a confounder vermillion; the kinds drawn."""
    drawn = set()
    for e in normal:
        kind = 'confounder' if e.get('confounder') else 'normal'
        colour = palette.NORMAL[kind]
        if e['kind'] == 'rib' and e.get('line_mm'):
            line = np.asarray(e['line_mm'], float)
            ax.plot(line[:, 1], line[:, 2], color=colour, lw=1.5, ls=':', zorder=2.5)
        elif e['kind'] == 'nodule' and e.get('surface_mm') is not None:
            ax.add_patch(_circle(e['surface_mm'][1:], e['radius_mm'], colour))
        else:
            continue
        drawn.add(kind)
    return drawn


def _circle(centre, radius: float, colour: str):
    """A dotted circle patch of ``radius`` [mm] at ``centre`` (y, z) [mm]."""
    return Circle(tuple(centre), radius, fill=False, lw=1.2, ls=':', zorder=2.5, color=colour)


def _frame(ax, R):
    ax.set_xlim(-R - 5, R + 5)
    ax.set_ylim(-R - 5, R + 5)
    ax.set_aspect('equal')
    ax.set_xlabel('y [mm]')
    ax.set_ylabel('z [mm]')
