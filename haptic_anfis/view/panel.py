"""The debrief's side panel as Markdown (no ROS, no viser): the headline numbers rounded as a
person reads them, the trainee's history as a table narrow enough for the panel of a 1280 x 800
window. Every text a user typed or a file named is escaped (:func:`.escape.md`).
"""
from __future__ import annotations

from .escape import md

__all__ = ['duration_text', 'effort_rows', 'history_markdown', 'numbers_markdown']


def duration_text(seconds: float) -> str:
    """``seconds`` [s] as a person says it: '45 s', '3 min 4 s', '1 h 2 min'."""
    s = int(round(float(seconds)))
    if s < 60:
        return f'{s} s'
    if s < 3600:
        return f'{s // 60} min {s % 60} s'
    return f'{s // 3600} h {s % 3600 // 60} min'


def numbers_markdown(n: dict) -> str:
    """The debrief's headline numbers (:func:`~.debrief.panel_numbers`), a few short lines:
    score and verdict, lumps found, coverage per level [%], pattern and duration, then what
    predicts finding lumps (:func:`effort_rows`). Rounded: the report (``exam report --json``)
    keeps the exact values."""
    cov = ' · '.join(f"{k} **{n[f'coverage_{k}_pct']:.0f} %**"
                     for k in ('light', 'medium', 'deep'))
    found = n['hits'] + n['misses']
    lines = [f"score **{n['score']:.0f}** — **{md(n['verdict'])}**",
             f"lumps found: **{n['hits']} of {found}** · false marks: **{n['false_marks']}**"
             + (f" ({n['false_marks_normal']} on normal tissue)"
                if n.get('false_marks_normal') else ''),
             f'coverage: {cov}',
             f"pattern: {md(str(n['pattern']).replace('_', ' '))} · duration "
             f"**{duration_text(n['duration_s'])}**"]
    lines += [f'{k}: {v}' for k, v in effort_rows(n)]
    return '\n'.join(f'- {line}' for line in lines)


def effort_rows(n: dict) -> list[tuple[str, str]]:
    """What predicts finding lumps (haptic_anfis.exam.effort) as (label, text) rows: time at
    each pressure level and over each area (whole seconds), the force palpating vs searching
    [N]; none for a report without them."""
    rows: list[tuple[str, str]] = []
    for key, label in (('time_at_level_s', 'time at pressure'), ('area_time_s', 'time over')):
        items = (n.get(key) or {}).items()
        if items:
            rows.append((label, ' · '.join(f"{k.replace('_', ' ')} {v:.0f} s" for k, v in items)))
    pal, sea = n.get('force_palpating_n'), n.get('force_searching_n')
    if pal is not None or sea is not None:
        f = lambda v: '-' if v is None else f'{v:.1f}'  # noqa: E731
        pct = n.get('palpating_vs_searching_pct')
        rows.append(('force palpating / searching',
                     f'{f(pal)} / {f(sea)} N' + (f' ({pct:+.0f} %)' if pct is not None else
                                                 ' (under 1 s of one: not compared)'
                                                 if pal is not None and sea is not None
                                                 else '')))
    return rows


#: the history table's columns: (heading, the row's value); short, so nine sessions fit the
#: panel's width (the case's name, long and a blind case's giveaway, is on the instructor's
#: console and in ``trainees show``)
_HISTORY_COLUMNS = (
    ('#', lambda r: r['session']), ('date', lambda r: (r['started_utc'] or '')[5:10]),
    ('lvl', lambda r: r['case_level'] or ''),
    ('deep', lambda r: f"{r['coverage_pct']['deep']:.0f} %"),
    ('found', lambda r: f"{r['hits']}/{r['hits'] + r['misses']}"),
    ('false', lambda r: r['false_marks']), ('score', lambda r: f"{r['score']:.0f}"),
    ('', lambda r: r['verdict']))


#: sessions the history table shows (the newest): with the debrief, the panel fits 800 px
HISTORY_ROWS = 5


def history_markdown(trainee: str, rows: list[dict]) -> str:
    """The trainee's last :data:`HISTORY_ROWS` sessions as a Markdown table
    (:func:`~.app.trainee_history` rows; ``trainees show`` has them all)."""
    if rows and 'error' in rows[0]:
        return f"trainee record: {md(rows[0]['error'])}"
    if not rows:
        return f'no earlier session of **{md(trainee)}**'
    head = '| ' + ' | '.join(h for h, _ in _HISTORY_COLUMNS) + ' |\n|' + '---|' * len(
        _HISTORY_COLUMNS)
    shown = min(len(rows), HISTORY_ROWS)
    body = ''.join('\n| ' + ' | '.join(md(f(r)) for _, f in _HISTORY_COLUMNS) + ' |'
                   for r in rows[-HISTORY_ROWS:])
    return f'**{md(trainee)}**: {len(rows)} sessions, the last {shown}\n\n' + head + body
