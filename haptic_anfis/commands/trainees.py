"""``haptic-anfis trainees``: the trainee record (sessions stored by ``exam run|report
--trainee-id ID``).

    haptic-anfis trainees list
    haptic-anfis trainees show ID [--instructor]
    haptic-anfis trainees progress ID [--json] [--figure PNG] [--instructor]

What they print is what the trainee may see: a blind session's (``exam run --next``) case is
named only with ``--instructor`` (and in ``export``, an instructor's file).
    haptic-anfis trainees export ID --csv [-o FILE]
    haptic-anfis trainees delete ID
"""
from __future__ import annotations

import argparse
import importlib
import io
import sys
import textwrap

from ..record import (delete_trainee, export_csv, history, load_mastery_config, mastery,
                      resolve_db_path, trainees)

NAME = 'trainees'

#: ``progress`` draws the learning curve (matplotlib): its own module
#: (``haptic_anfis.commands.<module>``), imported only when chosen, so the other actions do not
#: load matplotlib
ACTION_MODULES = {'progress': '_trainees_progress'}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('--db', default=None, metavar='PATH',
                   help='the record file (default $HAPTIC_ANFIS_DB, else '
                        '$XDG_DATA_HOME/haptic_anfis/trainees.sqlite)')
    sub = p.add_subparsers(dest='action', metavar='ACTION', required=True)
    lst = sub.add_parser('list', help='one row per trainee: sessions, last session, last score')
    s = sub.add_parser('show', help="a trainee's sessions, one row each, and mastery")
    s.add_argument('id', metavar='ID')
    g = sub.add_parser('progress', help='the learning curve: table, --json, --figure PNG')
    g.add_argument('id', metavar='ID')
    g.add_argument('--json', action='store_true', help='one JSON object (sessions + mastery)')
    g.add_argument('--figure', metavar='PNG', default=None, help='write the learning curve')
    g.add_argument('--exam-config', metavar='YAML', default=None,
                   help='mastery thresholds (default config/exam.yaml)')
    e = sub.add_parser('export', help="a trainee's sessions as CSV")
    e.add_argument('id', metavar='ID')
    e.add_argument('--csv', action='store_true', required=True, help='CSV (the one format)')
    e.add_argument('-o', '--output', metavar='FILE', default=None, help='file (default stdout)')
    d = sub.add_parser('delete', help='remove a trainee and every session of it (privacy)')
    d.add_argument('id', metavar='ID')
    for q in (s, g):
        q.add_argument('--instructor', action='store_true',
                       help="the instructor's view: name the case of a blind session (--next); "
                            'without it the output is what the trainee may see')
    for q in (lst, s, g, e, d):   # --db also after the action
        q.add_argument('--db', default=argparse.SUPPRESS, metavar='PATH', help=argparse.SUPPRESS)


def run(args: argparse.Namespace) -> int:
    db = resolve_db_path(args.db)
    if args.action in ACTION_MODULES:
        mod = importlib.import_module(f'{__package__}.{ACTION_MODULES[args.action]}')
        return getattr(mod, args.action)(args, db)
    actions = {'list': _list, 'show': _show, 'export': _export, 'delete': _delete}
    return actions[args.action](args, db)


def _list(args, db) -> int:
    rows = trainees(db)
    if not rows:
        print(f'no trainee in {db}')
        return 0
    print(f'{"trainee":<24} {"sessions":>8}  {"last session (UTC)":<26} {"score":>6}  verdict')
    for r in rows:
        score = '-' if r['last_score'] is None else f"{r['last_score']:.1f}"
        print(f"{r['id']:<24} {r['sessions']:>8}  {r['last_utc'] or '-':<26} {score:>6}  "
              f"{r['last_verdict'] or '-'}")
    return 0


#: the search patterns in the table's one word each
_PATTERN = {'vertical_strip': 'strips', 'spiral_circular': 'circles', 'radial': 'radial'}


def _table(sessions: list[dict]) -> None:
    """One line per session within 100 columns: when (UTC, to the minute), case, level,
    coverage light/medium/deep [%], pattern, marks, sensitivity, score, verdict (void when the
    loop fell behind: its reason below), time [s]."""
    print(f'{"#":>4} {"started UTC":<11} {"case":<14} {"lvl":>3} {"cover l/m/d":>11} '
          f'{"pattern":<7} {"hit":>3} {"miss":>4} {"false":>5} {"sens":>4} {"score":>5} '
          f'{"verdict":<7} {"time s":>6}')
    for s in sessions:
        c = s['coverage_pct']
        sens = '-' if s['sensitivity'] is None else f"{100 * s['sensitivity']:.0f}%"
        case = (s['case'] or '-')[-14:]
        cover = '/'.join(f'{c[k]:.0f}' for k in ('light', 'medium', 'deep'))
        when = (s['started_utc'] or '')[5:16].replace('T', ' ')
        pattern = _PATTERN.get(s['pattern'], s['pattern'] or '-')[:7]
        print(f"{s['session']:>4} {when:<11} {case:<14} "
              f"{s['case_level'] if s['case_level'] is not None else '-':>3} {cover:>11} "
              f"{pattern:<7} {s['hits']:>3} {s['misses']:>4} {s['false_marks']:>5} {sens:>4} "
              f"{s['score']:>5.0f} {'void' if s.get('void') else s['verdict']:<7} "
              f"{s['duration_s']:>6.0f}")
    for s in sessions:
        if s.get('void'):
            print(textwrap.fill(f"session {s['session']} is void: {s['void']}", 100,
                                initial_indent='  ', subsequent_indent='    '))


def _mastery_lines(m: dict, config=None) -> None:
    """The mastery (:func:`~haptic_anfis.record.mastery`) per level, with its window's false
    marks per case against ``config``'s limit (a MasteryConfig; None: not said), and the
    trainee's specificity over the sessions."""
    print(f"mastered level {m['mastered_level'] or 'none'}; next level {m['next_level']}")
    for L, v in m['levels'].items():
        more = ''.join(f', {n} {what}' for n, what in (
            (v.get('lesion_free', 0), 'without a lump'), (v.get('void', 0), 'void')) if n)
        limit = None if config is None else config.levels[L].max_false_marks_per_case
        if v.get('false_marks_per_case') is not None:   # specificity over the window
            more += (f", false marks {v['false_marks_per_case']:.2f} per case over the last "
                     f"{v['window_cases']}" + ('' if limit is None else f' (at most {limit:g})'))
        print(f"  level {L}: {v['sessions']} session(s) with a lump, {v['met']} met the "
              f"thresholds, {v['best_streak']}/{v['needed']} in a row"
              f"{' - mastered' if v['mastered'] else ''}{more}")
    sp = m.get('specificity')
    if sp and sp['sessions']:
        split = ('' if sp['normal_per_session'] is None else
                 f" ({sp['normal_per_session']:.2f} on normal tissue, "
                 f"{sp['elsewhere_per_session']:.2f} elsewhere, of {sp['split_sessions']} "
                 'session(s) that tell)')
        print(f"specificity: {sp['clean']} of {sp['sessions']} session(s) without a false mark "
              f"({sp['clean_pct']:.0f} %); {sp['false_marks_per_session']:.2f} false marks per "
              f'session{split}')


def _show(args, db) -> int:
    sessions = history(db, args.id, instructor=args.instructor)
    print(f'trainee {args.id}: {len(sessions)} session(s) in {db}')
    _table(sessions)
    cfg = load_mastery_config()
    _mastery_lines(mastery(sessions, cfg), cfg)
    for s in sessions:
        if s['bag']:
            print(f"  session {s['session']}: bag {s['bag']}")
    return 0


def _export(args, db) -> int:
    if args.output:
        text = io.StringIO()
        n = export_csv(db, args.id, text)   # first: an unknown id must not empty an old export
        with open(args.output, 'w', newline='') as f:
            f.write(text.getvalue())
        print(f'{n} session(s) of {args.id} written to {args.output}', file=sys.stderr)
    else:
        export_csv(db, args.id, sys.stdout)
    return 0


def _delete(args, db) -> int:
    n = delete_trainee(db, args.id)
    print(f'trainee {args.id} deleted from {db}: {n} session(s) removed')
    return 0
