"""One trainee's learning curves as an image for the instructor's console (matplotlib Agg, no
ROS): per session, the score and the coverage at each pressure level, with a legend.

Colour-blind safe: Okabe & Ito's palette (2008; distinguishable in the common colour-vision
deficiencies), and every series has its own marker and line style too, so the legend reads in
grey as well.
"""
from __future__ import annotations

import numpy as np

__all__ = ['OKABE_ITO', 'SERIES', 'curves_image']

#: Okabe & Ito's colour-blind safe palette
OKABE_ITO = {'orange': '#E69F00', 'sky blue': '#56B4E9', 'bluish green': '#009E73',
             'yellow': '#F0E442', 'blue': '#0072B2', 'vermillion': '#D55E00',
             'reddish purple': '#CC79A7', 'black': '#000000'}
#: (legend label, the session's value, colour, marker, line style)
SERIES = (('score', lambda s: s['score'], OKABE_ITO['black'], 'o', '-'),
          ('deep coverage %', lambda s: s['coverage_pct']['deep'], OKABE_ITO['vermillion'], 's',
           '-'),
          ('medium coverage %', lambda s: s['coverage_pct']['medium'], OKABE_ITO['blue'], '^',
           '--'),
          ('light coverage %', lambda s: s['coverage_pct']['light'], OKABE_ITO['orange'], 'v',
           ':'))


def curves_image(trainee: str, sessions: list[dict], size: tuple[float, float] = (5.0, 3.0),
                 dpi: int = 80) -> np.ndarray:
    """(h, w, 3) uint8 RGB: ``trainee``'s curves over ``sessions`` (oldest first,
    :func:`~haptic_anfis.record.history` dicts)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=size, dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    x = np.arange(1, len(sessions) + 1)
    for label, value, colour, marker, ls in SERIES:
        ax.plot(x, [value(s) for s in sessions], color=colour, marker=marker, ls=ls,
                label=label)
    ax.set_ylim(-3, 103)
    ax.set_xlabel('session')
    ax.set_ylabel('score / coverage [%]')
    ax.set_title(f'{trainee}: {len(sessions)} session{"s" * (len(sessions) != 1)}', fontsize=9)
    if len(sessions):
        ax.set_xticks(x if len(x) <= 15 else x[::max(1, len(x) // 10)])
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc='lower right')
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
