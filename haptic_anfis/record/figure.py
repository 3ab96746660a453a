"""The learning-curve figure of one trainee (PNG, matplotlib Agg, no ROS): per session, coverage
per pressure level, sensitivity, false marks, time, and the case level with the mastered level."""
from __future__ import annotations

import os

__all__ = ['save_progress_figure']

_LEVEL_COLOURS = {'light': '#9ecae1', 'medium': '#4292c6', 'deep': '#08306b'}


def save_progress_figure(trainee_id: str, sessions: list[dict], path: str | os.PathLike,
                         mastery: dict | None = None, pass_deep_pct: float | None = None) -> None:
    """Write the learning curve of ``sessions`` (:func:`~haptic_anfis.record.history` dicts,
    oldest first) to ``path``; ``mastery`` (:func:`~haptic_anfis.record.mastery`) adds the
    mastered level, ``pass_deep_pct`` [%] a line at the deep-coverage threshold."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    n = len(sessions)
    x = list(range(1, n + 1))
    fig, axes = plt.subplots(5, 1, figsize=(8, 11), sharex=True,
                             gridspec_kw={'height_ratios': [2, 1, 1, 1, 1]})
    ax = axes[0]
    for (lev, col), ms, ls in zip(_LEVEL_COLOURS.items(), (10, 7, 4), ('-', '--', '-')):
        # equal levels overlap: decreasing markers keep all three visible
        ax.plot(x, [s['coverage_pct'][lev] for s in sessions], 'o', ls=ls, ms=ms, color=col,
                label=lev)
    if pass_deep_pct is not None:
        ax.axhline(pass_deep_pct, color='#08306b', ls=':', lw=1,
                   label=f'deep threshold {pass_deep_pct:.0f} %')
    ax.set_ylim(-3, 103)
    ax.set_ylabel('coverage [%]')
    ax.legend(loc='lower right', fontsize=8, ncol=2)
    title = f'trainee {trainee_id}: {n} session{"s" * (n != 1)}'
    if mastery is not None:
        title += f", mastered level {mastery['mastered_level'] or 'none'}, next " \
                 f"{mastery['next_level']}"
    ax.set_title(title)

    ax = axes[1]
    sx = [i for i, s in zip(x, sessions) if s['sensitivity'] is not None]
    ax.plot(sx, [100 * s['sensitivity'] for s in sessions if s['sensitivity'] is not None],
            's-', color='#238b45')
    none = [i for i, s in zip(x, sessions) if s['sensitivity'] is None]
    ax.plot(none, [50] * len(none), 'x', color='grey', ls='none',
            label='no palpable lesion' if none else None)
    if none:
        ax.legend(loc='center left', fontsize=8)
    ax.set_ylim(-5, 105)
    ax.set_ylabel('sensitivity [%]\n(palpable found)')

    ax = axes[2]
    fm = [s['false_marks'] for s in sessions]
    ax.bar(x, fm, color='#cb181d', width=0.6)
    ax.set_ylim(0, max(fm + [1]) + 0.5)
    ax.set_ylabel('false marks')
    ax.yaxis.get_major_locator().set_params(integer=True)

    ax = axes[3]
    ax.bar(x, [s['duration_s'] for s in sessions], color='#bdbdbd', width=0.6, label='session')
    ax.bar(x, [s['contact_s'] or 0.0 for s in sessions], color='#636363', width=0.35,
           label='in contact')
    ax.set_ylabel('time [s]')
    ax.set_ylim(0, 1.4 * max([s['duration_s'] for s in sessions] + [1.0]))
    ax.legend(loc='upper left', fontsize=8, ncol=2)

    ax = axes[4]
    lv = [s['case_level'] for s in sessions]
    ax.step(x, [v if v is not None else float('nan') for v in lv], where='mid', color='#6a51a3')
    for i, s in zip(x, sessions):
        if s['case_level'] is not None:
            ax.plot(i, s['case_level'], 'o', ms=8, mfc='#31a354' if s['verdict'] == 'pass'
                    else '#fdae6b', mec='k')
    if mastery is not None and mastery['mastered_level']:
        ax.axhline(mastery['mastered_level'], color='#31a354', ls='--', lw=1,
                   label=f"mastered {mastery['mastered_level']}")
        ax.legend(loc='upper left', fontsize=8)
    top = max([v for v in lv if v is not None] + [1])
    ax.set_ylim(0.5, top + 0.5)
    ax.set_yticks(range(1, top + 1))
    ax.set_ylabel('case level\n(dot: pass/retry)')
    ax.set_xlabel('session')
    ax.set_xticks(x if n <= 30 else x[::max(1, n // 15)])
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
