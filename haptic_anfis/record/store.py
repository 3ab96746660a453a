"""Store scored exam sessions in the trainee record and read them back.

A session row keeps the headline figures as columns (for queries, progress and mastery) and the
full exam report as JSON (``report_json``: coverage per level, pattern, marks, lesions, feedback,
notes...). Each :func:`store_session` is ONE transaction: the trainee row (created on its first
session) and the session row are committed together or not at all. Pure Python, no ROS.
"""
from __future__ import annotations

import csv
import json
import os
import unicodedata
from datetime import datetime, timezone
from typing import IO

from .db import RecordError, connect, resolve_db_path, write

__all__ = ['BLIND_CASE', 'CSV_COLUMNS', 'WALL_CLOCK_NS', 'AlreadyStored', 'UnknownTrainee',
           'check_trainee_id', 'delete_trainee', 'export_csv', 'history', 'not_palpable_of',
           'same_recording', 'session_report', 'session_row', 'store_session', 'trainees',
           'utc_iso']

#: what a trainee id may hold besides letters and digits (of any script)
ID_PUNCTUATION = '._@+-'

#: the columns of ``trainees export --csv`` (one row per session, oldest first)
CSV_COLUMNS = ('session', 'started_utc', 'source', 'case', 'case_level', 'coverage_light_pct',
               'coverage_medium_pct', 'coverage_deep_pct', 'pattern', 'lesions', 'hits',
               'misses', 'palpable_missed', 'not_palpable', 'false_marks', 'false_marks_normal',
               'sensitivity',
               'score', 'verdict', 'duration_s', 'contact_s', 'bag', 'void', 'blind')


class UnknownTrainee(RecordError):
    """The trainee id has no row in the record (the message names the file)."""


class AlreadyStored(RecordError):
    """The trainee already has a session scored from this bag (``session``: its id): a bag
    counts once, or scoring it again would count toward mastery again."""

    def __init__(self, message: str, session: int):
        super().__init__(message)
        self.session = session


def check_trainee_id(trainee_id: str) -> str:
    """``trainee_id`` if it is 1-64 letters or digits of any script (``str.isalnum``: a trainee
    writes their pseudonym in their own alphabet, "Zoë", "Łukasz", "明") or ``._@+-``, starting
    with a letter or digit, in Unicode's composed form (NFC: one id is one string, whichever way
    a keyboard typed "ë"); else ValueError naming it. No space, no control or markup
    character. Use a pseudonym: the record needs no real name."""
    ok = (isinstance(trainee_id, str) and 1 <= len(trainee_id) <= 64
          and trainee_id[0].isalnum()
          and all(c.isalnum() or c in ID_PUNCTUATION for c in trainee_id))
    if not ok:
        raise ValueError(f'--trainee-id {trainee_id!r}: expected 1-64 letters (of any '
                         f'alphabet), digits or {ID_PUNCTUATION} (starting with a letter or digit)')
    if unicodedata.normalize('NFC', trainee_id) != trainee_id:
        raise ValueError(f'--trainee-id {trainee_id!r}: expected composed Unicode (NFC), e.g. '
                         f'{unicodedata.normalize("NFC", trainee_id)!r}')
    return trainee_id


def utc_iso(t_s: float | None = None) -> str:
    """``t_s`` (seconds since the epoch; None = now) as the record writes times: ISO 8601, UTC,
    to the second (so they sort as text)."""
    t = datetime.now(timezone.utc) if t_s is None else datetime.fromtimestamp(t_s, timezone.utc)
    return t.isoformat(timespec='seconds')


def not_palpable_of(report: dict) -> list[str]:
    """Names of the lesions the report says cannot be felt: ``report['not_palpable']`` (names or
    dicts with ``name``) when the exam gives it, else lesions with ``palpable: false``; [] when
    the exam does not grade palpability."""
    given = report.get('not_palpable')
    if given is None:
        return [str(les.get('name')) for les in report.get('lesions', ())
                if les.get('palpable') is False]
    return [str(x.get('name') if isinstance(x, dict) else x) for x in given]


def session_row(report: dict, *, source: str, case_level: int | None = None,
                bag: str | None = None, started_utc: str | None = None) -> dict:
    """The column values of one session from an exam ``report`` (``ExamSession.report()`` plus
    ``case`` / ``bag``). Pure.

    Raises:
        ValueError: the report lacks a headline field (it is not a scored exam report).
    """
    try:
        cov = report['coverage_pct']
        lesions = list(report.get('lesions', ()))
        hidden = not_palpable_of(report)
        palpable_missed = sum(1 for les in lesions
                              if not les.get('found') and str(les.get('name')) not in hidden)
        return {
            'started_utc': started_utc or utc_iso(), 'stored_utc': utc_iso(), 'source': source,
            'case_name': report.get('case'), 'case_level': case_level,
            'bag_path': bag if bag is not None else report.get('bag'),
            'coverage_light': float(cov['light']), 'coverage_medium': float(cov['medium']),
            'coverage_deep': float(cov['deep']), 'pattern': report.get('pattern'),
            'lesions': len(lesions), 'hits': int(report['hits']),
            'misses': int(report['misses']), 'false_marks': int(report['false_marks']),
            'score': float(report['score']), 'verdict': str(report['verdict']),
            'duration_s': float(report['duration_s']),
            'contact_s': float(report.get('contact_s', 0.0)),
            'not_palpable': json.dumps(hidden), 'palpable_missed': palpable_missed,
            'void_reason': report.get('void_reason') or None,
            # schema v6: of the false marks, those on a normal lobule or rib (None: not known)
            'false_marks_normal': _int_or_none(report.get('false_marks_normal')),
            'blind': int(bool(report.get('blind'))),
            'report_json': json.dumps(report, allow_nan=False, default=str),
            # what predicts finding lumps (haptic_anfis.exam.effort); None in an older report
            'time_at_level_json': _json_or_none(report.get('time_at_level_s')),
            'area_time_json': _json_or_none(report.get('area_time_s')),
            'force_palpating_n': report.get('force_palpating_n'),
            'force_searching_n': report.get('force_searching_n'),
            'lesion_levels_json': json.dumps({str(les.get('name')): les.get('level')
                                              for les in lesions}),
        }
    except (KeyError, TypeError) as exc:
        raise ValueError(f'exam report: missing or bad field {exc}') from None


def _json_or_none(v) -> str | None:
    return None if v is None else json.dumps(v)


def _int_or_none(v) -> int | None:
    return None if v is None else int(v)


#: first-message times from here on [ns] are wall clock (after 2001); earlier ones are a
#: simulation's clock, which two recordings can share
WALL_CLOCK_NS = 10**18


def same_recording(path_a: str | None, start_a: int | None, path_b: str | None,
                   start_b: int | None) -> bool:
    """Whether two stored sessions' bags (absolute path, first message [ns] or None) are one
    recording: the same wall-clock first message wherever the bag is now (a copy), or the same
    path unless both know their first message and it differs (a bag deleted and recorded again
    there). A side that does not know its start (stored before schema v3, or the bag
    unreadable) counts as that recording: better one session too few than one twice.
    :func:`store_session` and :func:`~haptic_anfis.record.mastery.mastery` ask this."""
    if path_a is None or path_b is None:
        return False
    if start_a is not None and start_a == start_b and start_a >= WALL_CLOCK_NS:
        return True
    return path_a == path_b and (start_a is None or start_b is None or start_a == start_b)


def store_session(db: str | os.PathLike | None, trainee_id: str, report: dict, *,
                  source: str = 'run', case_level: int | None = None, bag: str | None = None,
                  started_utc: str | None = None, bag_start_ns: int | None = None) -> int:
    """Store one scored session for ``trainee_id`` (created on its first session) in ONE
    transaction; returns the session id. ``bag_start_ns``: the bag's first message's time
    [ns], which tells two recordings made at the same path apart.

    Raises:
        ValueError: bad trainee id or report; RecordError (a ValueError): the file;
            AlreadyStored (a RecordError): ``bag`` is already stored for this trainee (a
            recording counts once toward mastery; nothing is stored): :func:`same_recording`.
    """
    check_trainee_id(trainee_id)
    row = session_row(report, source=source, case_level=case_level, bag=bag,
                      started_utc=started_utc)
    row['bag_start_ns'] = None if bag_start_ns is None else int(bag_start_ns)
    cols = ', '.join(row)
    marks = ', '.join(f':{k}' for k in row)

    def tx(conn):
        if row['bag_path'] is not None:
            # the candidates (same path or same start), then same_recording decides: one rule
            # for the store and for mastery()
            old = next((r for r in conn.execute(
                'SELECT id, bag_path, bag_start_ns FROM sessions WHERE trainee_id = :t AND '
                '(bag_path = :p OR bag_start_ns = :ns) ORDER BY id',
                {'t': trainee_id, 'p': row['bag_path'], 'ns': row['bag_start_ns']})
                if same_recording(r[1], r[2], row['bag_path'], row['bag_start_ns'])), None)
            if old is not None:
                raise AlreadyStored(
                    f'bag {row["bag_path"]!r} is already stored as session {old[0]} of trainee '
                    f'{trainee_id} in {str(resolve_db_path(db))!r}: a recording counts once '
                    'toward mastery; not stored again', int(old[0]))
        conn.execute('INSERT OR IGNORE INTO trainees (id, created_utc) VALUES (?, ?)',
                     (trainee_id, row['stored_utc']))
        cur = conn.execute(f'INSERT INTO sessions (trainee_id, {cols}) VALUES (:trainee_id, '
                           f'{marks})', {'trainee_id': trainee_id, **row})
        return int(cur.lastrowid)
    return write(db, tx)


def trainees(db: str | os.PathLike | None = None) -> list[dict]:
    """One dict per trainee: ``id``, ``created_utc``, ``sessions``, ``last_utc``, ``last_score``,
    ``last_verdict`` (the last session by its start, as :func:`history` orders them); [] when
    the record file does not exist yet.

    Raises:
        RecordError: the path is a folder, or a bad file (naming it).
    """
    if not resolve_db_path(db).exists():
        return []
    last = ('(SELECT {} FROM sessions WHERE trainee_id = t.id '
            'ORDER BY started_utc DESC, id DESC LIMIT 1)')
    with connect(db) as conn:
        rows = conn.execute(
            f'SELECT t.id, t.created_utc, count(s.id), {last.format("started_utc")}, '
            f'{last.format("score")}, {last.format("verdict")} '
            'FROM trainees t LEFT JOIN sessions s ON s.trainee_id = t.id '
            'GROUP BY t.id ORDER BY t.id').fetchall()
    return [dict(zip(('id', 'created_utc', 'sessions', 'last_utc', 'last_score',
                      'last_verdict'), r)) for r in rows]


_HISTORY_COLS = ('id', 'started_utc', 'source', 'case_name', 'case_level', 'bag_path',
                 'coverage_light', 'coverage_medium', 'coverage_deep', 'pattern', 'lesions',
                 'hits', 'misses', 'palpable_missed', 'not_palpable', 'false_marks', 'score',
                 'verdict', 'duration_s', 'contact_s', 'bag_start_ns', 'time_at_level_json',
                 'area_time_json', 'force_palpating_n', 'force_searching_n',
                 'lesion_levels_json', 'void_reason', 'blind', 'false_marks_normal')

#: what the trainee's view of the record shows for a blind session's case
BLIND_CASE = 'blind'


def _loads(text: str | None):
    return None if text is None else json.loads(text)


def _known(conn, db, trainee_id: str) -> None:
    if conn.execute('SELECT 1 FROM trainees WHERE id = ?', (trainee_id,)).fetchone() is None:
        known = [r[0] for r in conn.execute('SELECT id FROM trainees ORDER BY id LIMIT 20')]
        raise UnknownTrainee(f'unknown trainee id {trainee_id!r} in trainee record '
                          f'{str(resolve_db_path(db))!r} (known: {", ".join(known) or "none"})')


def history(db: str | os.PathLike | None, trainee_id: str, full: bool = False,
            instructor: bool = False) -> list[dict]:
    """The sessions of ``trainee_id``, oldest first (by their start; sessions stored in
    another order, a bag scored later, take their place), one dict each (the browser view's
    call):

    ``session`` (id), ``started_utc`` (ISO 8601, UTC), ``source`` ('run' / 'bag'), ``case``,
    ``case_level``, ``bag``, ``bag_start_ns`` (its first message [ns], None if not known),
    ``coverage_pct`` {light, medium, deep} [%], ``pattern``,
    ``lesions``, ``hits``, ``misses``, ``palpable_missed``, ``not_palpable`` (names),
    ``false_marks``, ``false_marks_normal`` / ``false_marks_elsewhere`` (of them, on a normal
    lobule or rib / elsewhere; None for a session stored before schema v6 from a report without
    the split), ``sensitivity`` (found / palpable lesions, None without one), ``score``,
    ``verdict``, ``duration_s``, ``contact_s`` [s], ``time_at_level_s`` and ``area_time_s``
    ({name: s}), ``force_palpating_n`` / ``force_searching_n`` [N], ``lesion_levels`` ({lesion:
    the pressure level it is felt from}; these None for a session stored before schema v4),
    ``void`` (why the session does not count toward mastery: its haptic loop fell behind; None
    for a session that counts), ``blind`` (drawn by ``exam run --next``); with ``full``,
    ``report`` (the stored exam report).

    What the trainee may see unless ``instructor``: a blind session's ``case`` is
    :data:`BLIND_CASE` (a case name gives its lesions' size and depth away) and its ``report``
    names no case; ``instructor`` (the instructor's console, the blind draw) gives every name.

    Raises:
        RecordError: no record file, unknown trainee (the message names the file), bad file.
    """
    check_trainee_id(trainee_id)
    with connect(db) as conn:
        _known(conn, db, trainee_id)
        extra = ', report_json' if full else ''
        rows = conn.execute(f'SELECT {", ".join(_HISTORY_COLS)}{extra} FROM sessions '
                            'WHERE trainee_id = ? ORDER BY started_utc, id',
                            (trainee_id,)).fetchall()
    out = []
    for r in rows:
        d = dict(zip(_HISTORY_COLS, r))
        hidden = json.loads(d['not_palpable'] or '[]')
        palpable = d['lesions'] - len(hidden)
        missed = d['palpable_missed'] if d['palpable_missed'] is not None else d['misses']
        hide = bool(d['blind']) and not instructor
        h = {'session': d['id'], 'started_utc': d['started_utc'], 'source': d['source'],
             'case': BLIND_CASE if hide else d['case_name'], 'case_level': d['case_level'],
             'bag': d['bag_path'],
             'bag_start_ns': d['bag_start_ns'],
             'coverage_pct': {'light': d['coverage_light'], 'medium': d['coverage_medium'],
                              'deep': d['coverage_deep']},
             'pattern': d['pattern'], 'lesions': d['lesions'], 'hits': d['hits'],
             'misses': d['misses'], 'palpable_missed': missed, 'not_palpable': hidden,
             'false_marks': d['false_marks'],
             # schema v6 (None before, or from a report without the split): of the false marks,
             # those on a normal lobule or rib, and those elsewhere
             'false_marks_normal': d['false_marks_normal'],
             'false_marks_elsewhere': (None if d['false_marks_normal'] is None
                                       else d['false_marks'] - d['false_marks_normal']),
             'sensitivity': round((palpable - missed) / palpable, 4) if palpable > 0 else None,
             'score': d['score'], 'verdict': d['verdict'], 'duration_s': d['duration_s'],
             'contact_s': d['contact_s'],
             # schema v4 (None for a session stored before): time per pressure level and per
             # area [s], mean force palpating / searching [N], each lesion's pressure level
             'time_at_level_s': _loads(d['time_at_level_json']),
             'area_time_s': _loads(d['area_time_json']),
             'force_palpating_n': d['force_palpating_n'],
             'force_searching_n': d['force_searching_n'],
             'lesion_levels': _loads(d['lesion_levels_json']),
             'void': d['void_reason'], 'blind': bool(d['blind'])}
        if full:
            h['report'] = json.loads(r[-1])
            if hide:
                h['report']['case'] = BLIND_CASE
        out.append(h)
    return out


def session_report(db: str | os.PathLike | None, session_id: int) -> dict:
    """The full stored exam report of session ``session_id``.

    Raises:
        RecordError: no such session (naming the file), bad file.
    """
    with connect(db) as conn:
        row = conn.execute('SELECT report_json FROM sessions WHERE id = ?',
                           (int(session_id),)).fetchone()
    if row is None:
        raise RecordError(f'no session {session_id} in trainee record '
                          f'{str(resolve_db_path(db))!r}')
    return json.loads(row[0])


def delete_trainee(db: str | os.PathLike | None, trainee_id: str) -> int:
    """Remove ``trainee_id`` and every one of its sessions (privacy), in one transaction, with
    ``secure_delete`` (freed pages zeroed) and the WAL checkpointed and truncated afterwards so
    no copy of the rows stays in the file; returns the number of sessions removed.

    Raises:
        RecordError: unknown trainee / bad file.
    """
    check_trainee_id(trainee_id)
    if not resolve_db_path(db).is_file():
        with connect(db):   # raises: no such file
            pass

    def tx(conn):
        _known(conn, db, trainee_id)
        conn.execute('PRAGMA secure_delete = ON')
        n = conn.execute('DELETE FROM sessions WHERE trainee_id = ?', (trainee_id,)).rowcount
        conn.execute('DELETE FROM trainees WHERE id = ?', (trainee_id,))
        return n
    n = write(db, tx)
    with connect(db) as conn:
        conn.execute('PRAGMA wal_checkpoint(TRUNCATE)')
    return n


def export_csv(db: str | os.PathLike | None, trainee_id: str, out: IO[str]) -> int:
    """Write ``trainee_id``'s sessions as CSV (:data:`CSV_COLUMNS`, a header row first) to
    ``out``; returns the number of sessions."""
    rows = history(db, trainee_id, instructor=True)   # an instructor's or researcher's file
    w = csv.writer(out, lineterminator='\n')
    w.writerow(CSV_COLUMNS)
    for h in rows:
        c = h['coverage_pct']
        w.writerow([h['session'], h['started_utc'], h['source'], h['case'], h['case_level'],
                    c['light'], c['medium'], c['deep'], h['pattern'], h['lesions'], h['hits'],
                    h['misses'], h['palpable_missed'], ';'.join(h['not_palpable']),
                    h['false_marks'],
                    '' if h['false_marks_normal'] is None else h['false_marks_normal'],
                    '' if h['sensitivity'] is None else h['sensitivity'],
                    h['score'], h['verdict'], h['duration_s'], h['contact_s'], h['bag'] or '',
                    h['void'] or '', int(h['blind'])])
    return len(rows)
