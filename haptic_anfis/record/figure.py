"""The learning-curve figure of one trainee (PNG, matplotlib Agg, no ROS): per session, coverage
per pressure level, sensitivity, false marks (those on normal tissue apart), time, and the case
level with the mastered level. Colours: the picture language of every figure and the page (:mod:`haptic_anfis.palette`)."""
from __future__ import annotations

import os

from .. import palette

try:  # matplotlib: an optional dependency (the 'report' and 'fe' extras); PNG files, no display
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
except ImportError:
    plt = None

__all__ = ['save_progress_figure']

def save_progress_figure(trainee_id: str, sessions: list[dict], path: str | os.PathLike,
                         mastery: dict | None = None, pass_deep_pct: float | None = None) -> None:
    """Write the learning curve of ``sessions`` (:func:`~haptic_anfis.record.history` dicts,
    oldest first) to ``path``; ``mastery`` (:func:`~haptic_anfis.record.mastery`) adds the
    mastered level, ``pass_deep_pct`` [%] a line at the deep-coverage threshold. Only what was
    measured is drawn: a session with no palpable lesion has no sensitivity (its column is
    shaded, not given a value)."""
    if plt is None:
        raise ImportError('the progress figure needs matplotlib (pip install matplotlib)')
    n = len(sessions)
    x = list(range(1, n + 1))
    fig, axes = plt.subplots(5, 1, figsize=(8.5, 12), sharex=True, layout='constrained',
                             gridspec_kw={'height_ratios': [2, 1, 1, 1, 1]})
    legend = dict(fontsize=8, loc='upper left', bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    free = [i for i, s in zip(x, sessions) if s['sensitivity'] is None]
    for a in axes:   # the sessions without a lump to find, shaded on every panel
        for i in free:
            a.axvspan(i - 0.5, i + 0.5, color='0.93', zorder=0, lw=0)
    ax = axes[0]
    for lev, ms in zip(palette.LEVEL, (10, 7, 4)):
        # equal levels overlap: decreasing markers keep all three visible
        ax.plot(x, [s['coverage_pct'][lev] for s in sessions], 'o-', ms=ms, mec='k', mew=0.5,
                lw=1.2, color=palette.LEVEL[lev], label=lev)
    if pass_deep_pct is not None:
        ax.axhline(pass_deep_pct, color=palette.LEVEL['deep'], ls=':', lw=1,
                   label=f'deep threshold {pass_deep_pct:.0f} %')
    ax.set_ylim(-3, 103)
    ax.set_ylabel('coverage [%]')
    ax.legend(title='deepest press', title_fontsize=8, **legend)
    title = f'trainee {trainee_id}: {n} session{"s" * (n != 1)}'
    if mastery is not None:
        title += f", mastered level {mastery['mastered_level'] or 'none'}, next " \
                 f"{mastery['next_level']}"
    ax.set_title(title)

    ax = axes[1]
    sx = [i for i, s in zip(x, sessions) if s['sensitivity'] is not None]
    ax.plot(sx, [100 * s['sensitivity'] for s in sessions if s['sensitivity'] is not None],
            's-', color=palette.SENSITIVITY, label='palpable lesions found')
    ax.legend(handles=[Line2D([], [], marker='s', color=palette.SENSITIVITY,
                              label='palpable lesions found'),
                       Patch(color='0.93', label='no palpable lesion\n(nothing to find)')],
              **legend)
    ax.set_ylim(-5, 105)
    ax.set_ylabel('sensitivity [%]')

    ax = axes[2]
    fm = [s['false_marks'] for s in sessions]
    ax.bar(x, fm, color=palette.MARK['false'], width=0.6, label='false marks')
    on = [s.get('false_marks_normal') or 0 for s in sessions]
    if any(on):   # of them, on a normal lobule or rib (sessions stored since schema v6)
        ax.bar(x, on, color=palette.NORMAL['normal'], width=0.6,
               label='of them on a normal lobule or rib')
    ax.set_ylim(0, max(fm + [1]) + 0.5)
    ax.set_ylabel('false marks')
    ax.yaxis.get_major_locator().set_params(integer=True)
    ax.legend(**legend)

    ax = axes[3]
    ax.bar(x, [s['duration_s'] for s in sessions], color=palette.TIME['session'], width=0.6,
           label='session')
    ax.bar(x, [s['contact_s'] or 0.0 for s in sessions], color=palette.TIME['contact'],
           width=0.35, label='in contact')
    ax.set_ylabel('time [s]')
    ax.set_ylim(0, 1.1 * max([s['duration_s'] for s in sessions] + [1.0]))
    ax.legend(**legend)

    ax = axes[4]
    lv = [s['case_level'] for s in sessions]
    ax.step(x, [v if v is not None else float('nan') for v in lv], where='mid', color='0.5',
            lw=1, zorder=1)
    for i, s in zip(x, sessions):
        if s['case_level'] is not None:
            what = 'void' if s.get('void') else 'pass' if s['verdict'] == 'pass' else 'retry'
            ax.plot(i, s['case_level'], 'o', ms=8, mfc=palette.OUTCOME[what], mec='k', zorder=2)
    handles = [Line2D([], [], marker='o', ls='none', ms=8, mfc=palette.OUTCOME[k], mec='k',
                      label=w) for k, w in (('pass', 'pass'), ('retry', 'retry'),
                                            ('void', 'void (loop behind)'))]
    if mastery is not None and mastery['mastered_level']:
        ax.axhline(mastery['mastered_level'], color=palette.OUTCOME['pass'], ls='--', lw=1)
        handles.append(Line2D([], [], color=palette.OUTCOME['pass'], ls='--',
                              label=f"mastered {mastery['mastered_level']}"))
    ax.legend(handles=handles, **legend)
    top = max([v for v in lv if v is not None] + [1])
    ax.set_ylim(0.5, top + 0.5)
    ax.set_yticks(range(1, top + 1))
    ax.set_ylabel('case level')
    ax.set_xlabel('session')
    ax.set_xlim(0.5, n + 0.5)
    ax.set_xticks(x if n <= 30 else x[::max(1, n // 15)])
    for a in axes:
        a.grid(alpha=0.3)
    fig.savefig(path, dpi=90, bbox_inches='tight', pad_inches=0.15)
    plt.close(fig)
