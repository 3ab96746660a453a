"""The trainee record (haptic_anfis.record, `haptic-anfis trainees`, `exam ... --trainee-id`):
storage in one transaction, schema versions, concurrent writers, killed writers, bad files,
mastery by case level, the blind next case, privacy delete."""
from __future__ import annotations

import csv
import io
import json
import os
import signal
import shutil
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from haptic_anfis.cli import main
from haptic_anfis.record import (AlreadyStored, RecordError, case_level, delete_trainee,
                                 export_csv, history, load_mastery_config, mastery, store_session,
                                 trainees)
from haptic_anfis.record import db as rdb
from haptic_anfis.record.draw import next_case
from haptic_anfis.record.levels import has_palpable_lesion
from haptic_anfis.record.mastery import MasteryConfig, MasteryLevel

ROOT = Path(__file__).resolve().parents[2]


def fake_report(rng, deep=None, found=True, false_marks=0, case='default', lesions=('idc',),
                **extra) -> dict:
    """A report with the keys ExamSession.report() gives (the ones the record reads), values
    drawn from ``rng`` unless given."""
    deep = float(rng.uniform(0, 100)) if deep is None else float(deep)
    les = [{'name': n, 'found': bool(found), 'missed': None if found else 'never palpated deep'}
           for n in lesions]
    hits = sum(x['found'] for x in les)
    return {'coverage_pct': {'light': min(100.0, deep + 5), 'medium': min(100.0, deep + 2),
                             'deep': deep},
            'duration_s': float(rng.uniform(30, 300)), 'contact_s': float(rng.uniform(10, 30)),
            'hits': hits, 'misses': len(les) - hits, 'false_marks': int(false_marks),
            'score': float(rng.uniform(0, 100)), 'verdict': 'retry', 'pattern': 'vertical_strip',
            'lesions': les, 'marks': [], 'notes': [], 'case': case, **extra}


@pytest.fixture
def db(tmp_path):
    return tmp_path / 'rec' / 'trainees.sqlite'


def test_store_and_history_round_trip_one_row_per_session(db, rng):
    reps = [fake_report(rng, case='two_lesions', lesions=('a', 'b'), found=k % 2)
            for k in range(4)]
    ids = [store_session(db, 'ann', r, case_level=2, bag=f'/bags/{k}') for k, r in enumerate(reps)]
    store_session(db, 'bo', fake_report(rng), case_level=1)
    h = history(db, 'ann', full=True)
    assert [s['session'] for s in h] == ids and ids == sorted(ids)
    for s, r, k in zip(h, reps, range(4)):
        assert s['report'] == r     # the full report, exactly
        assert s['coverage_pct'] == r['coverage_pct'] and s['score'] == r['score']
        assert s['hits'] == r['hits'] and s['misses'] == r['misses'] == s['palpable_missed']
        assert s['sensitivity'] == r['hits'] / 2 and s['bag'] == f'/bags/{k}'
        assert s['case'] == 'two_lesions' and s['case_level'] == 2 and s['not_palpable'] == []
    assert [(t['id'], t['sessions']) for t in trainees(db)] == [('ann', 4), ('bo', 1)]
    with sqlite3.connect(db) as c:
        assert c.execute('PRAGMA journal_mode').fetchone()[0] == 'wal'
        assert c.execute('PRAGMA user_version').fetchone()[0] == rdb.SCHEMA_VERSION


def test_not_palpable_lesions_are_kept_and_not_held_against_the_trainee(db, rng):
    """i29 grades palpability: a missed lesion the FE says cannot be felt is no palpable miss."""
    r = fake_report(rng, lesions=('big', 'tiny'), found=False, not_palpable=['tiny'])
    r['lesions'][0]['found'] = True
    r['hits'], r['misses'] = 1, 1
    store_session(db, 'cy', r)
    r2 = fake_report(rng, lesions=('big', 'tiny'), found=False)   # per-lesion flag instead
    r2['lesions'][1]['palpable'] = False
    store_session(db, 'cy', r2)
    a, b = history(db, 'cy')
    assert a['not_palpable'] == ['tiny'] and a['palpable_missed'] == 0 and a['sensitivity'] == 1
    assert b['not_palpable'] == ['tiny'] and b['palpable_missed'] == 1 and b['sensitivity'] == 0
    # a report without the field (today's exam) stores an empty list
    store_session(db, 'cy', fake_report(rng))
    assert history(db, 'cy')[-1]['not_palpable'] == []


def test_default_path_env_and_flag(tmp_path, monkeypatch):
    monkeypatch.setenv('XDG_DATA_HOME', str(tmp_path / 'xdg'))
    monkeypatch.delenv(rdb.DB_ENV, raising=False)
    assert rdb.resolve_db_path() == tmp_path / 'xdg' / 'haptic_anfis' / 'trainees.sqlite'
    monkeypatch.setenv(rdb.DB_ENV, str(tmp_path / 'env.sqlite'))
    assert rdb.resolve_db_path() == tmp_path / 'env.sqlite'
    assert rdb.resolve_db_path(tmp_path / 'flag.sqlite') == tmp_path / 'flag.sqlite'
    store_session(None, 'dee', fake_report(np.random.default_rng(0)))
    assert (tmp_path / 'env.sqlite').is_file()


def test_an_older_file_is_migrated_and_its_rows_kept(db):
    db.parent.mkdir(parents=True)
    c = sqlite3.connect(db, isolation_level=None)
    rdb.migrate(c, to=1)                     # the first layout (no palpability columns)
    c.execute("INSERT INTO trainees VALUES ('old', '2026-01-01T00:00:00+00:00')")
    c.execute("INSERT INTO sessions (trainee_id, started_utc, stored_utc, source, case_name, "
              "coverage_light, coverage_medium, coverage_deep, lesions, hits, misses, "
              "false_marks, score, verdict, duration_s, report_json) VALUES ('old', 't', 't', "
              "'run', 'default', 50, 40, 30, 1, 0, 1, 2, 12.5, 'retry', 60, '{}')")
    assert c.execute('PRAGMA user_version').fetchone()[0] == 1
    c.close()
    (s,) = history(db, 'old')
    assert s['palpable_missed'] == 1 and s['not_palpable'] == [] and s['false_marks'] == 2
    with sqlite3.connect(db) as c:
        assert c.execute('PRAGMA user_version').fetchone()[0] == rdb.SCHEMA_VERSION


def test_a_new_recording_at_a_path_used_before_is_a_new_session(db, rng):
    """An instructor who deletes a bag and records to its path again: the new recording (its
    first message later) is stored and counts; the same recording still counts once, also as
    a copy scored at another path; simulated-time bags at other paths are not taken for it."""
    wall = 1_795_000_000_000_000_000   # 2026, ns
    rep = fake_report(rng, deep=100, case='x')
    first = store_session(db, 'ann', rep, case_level=1, bag='/bags/s', bag_start_ns=wall)
    with pytest.raises(AlreadyStored, match=f'session {first}'):
        store_session(db, 'ann', rep, case_level=1, bag='/bags/s', bag_start_ns=wall)
    second = store_session(db, 'ann', rep, case_level=1, bag='/bags/s', bag_start_ns=wall + 9)
    with pytest.raises(AlreadyStored, match=f'session {first}'):   # start unknown: one of them
        store_session(db, 'ann', rep, case_level=1, bag='/bags/s')
    with pytest.raises(AlreadyStored, match=f'session {second}'):   # a copy, scored elsewhere
        store_session(db, 'ann', rep, case_level=1, bag='/copies/s', bag_start_ns=wall + 9)
    sim = store_session(db, 'ann', rep, case_level=1, bag='/sim/a', bag_start_ns=100)
    other = store_session(db, 'ann', rep, case_level=1, bag='/sim/b', bag_start_ns=100)
    h = history(db, 'ann')
    assert [(s['session'], s['bag_start_ns']) for s in h] == [
        (first, wall), (second, wall + 9), (sim, 100), (other, 100)]
    cfg = MasteryConfig({1: MasteryLevel(consecutive_sessions=3)})
    assert mastery(h, cfg)['levels'][1]['sessions'] == 4
    # a record holding one recording twice (from before the check): counted once, as the
    # store decides, at the same path or as a copy elsewhere
    dups = [dict(h[1], session=98), dict(h[1], session=99, bag='/copies/s')]
    assert mastery(h + dups, cfg)['levels'][1]['sessions'] == 4
    assert mastery(h + [dict(h[2], session=97, bag='/sim/c')], cfg)['levels'][1]['sessions'] == 5


def test_a_bag_stored_before_its_start_was_kept_still_counts_once(db, rng):
    """A session stored by a version that kept no bag start (schema v2): scoring that path
    again is refused as before, whatever the new start (it may be the same recording)."""
    db.parent.mkdir(parents=True)
    c = sqlite3.connect(db, isolation_level=None)
    rdb.migrate(c, to=2)
    c.execute("INSERT INTO trainees VALUES ('old', '2026-01-01T00:00:00+00:00')")
    c.execute("INSERT INTO sessions (trainee_id, started_utc, stored_utc, source, case_name, "
              "case_level, bag_path, coverage_light, coverage_medium, coverage_deep, lesions, "
              "hits, misses, false_marks, score, verdict, duration_s, report_json) VALUES "
              "('old', 't', 't', 'bag', 'x', 1, '/bags/s', 50, 40, 30, 1, 0, 1, 0, 12.5, "
              "'retry', 60, '{}')")
    c.close()
    with pytest.raises(AlreadyStored):
        store_session(db, 'old', fake_report(rng), case_level=1, bag='/bags/s', bag_start_ns=5)
    (s,) = history(db, 'old')
    assert s['bag_start_ns'] is None


def test_a_newer_file_is_refused_untouched(db, rng):
    store_session(db, 'eve', fake_report(rng))
    with sqlite3.connect(db) as c:
        c.execute('PRAGMA user_version = 99')
    before = db.read_bytes()
    with pytest.raises(RecordError, match='newer') as e:
        store_session(db, 'eve', fake_report(rng))
    assert str(db) in str(e.value) and '\n' not in str(e.value)
    with pytest.raises(RecordError, match='newer'):
        history(db, 'eve')
    assert db.read_bytes() == before


def test_refused_files_are_not_even_switched_to_wal(tmp_path, rng):
    """A file refused (newer schema, another program's database) keeps its journal mode and
    bytes: the check comes before any PRAGMA that writes."""
    newer, other = tmp_path / 'newer.sqlite', tmp_path / 'other.sqlite'
    with sqlite3.connect(newer) as c:
        c.execute('PRAGMA user_version = 99')
        c.execute('CREATE TABLE t (a)')
    with sqlite3.connect(other) as c:
        c.execute('PRAGMA application_id = 1234')
        c.execute('CREATE TABLE x (a)')
    for path, what in ((newer, 'newer'), (other, 'not a trainee record')):
        before = path.read_bytes()
        for call in (lambda: store_session(path, 'f', fake_report(rng)),
                     lambda: history(path, 'f'), lambda: trainees(path)):
            with pytest.raises(RecordError, match=what):
                call()
        assert path.read_bytes() == before, path
        with sqlite3.connect(path) as c:
            assert c.execute('PRAGMA journal_mode').fetchone()[0] == 'delete'


def test_a_folder_given_as_the_record_is_one_line_saying_so(tmp_path, rng):
    folder = tmp_path / 'data'
    folder.mkdir()
    for call in (lambda: trainees(folder), lambda: history(folder, 'f'),
                 lambda: store_session(folder, 'f', fake_report(rng))):
        with pytest.raises(RecordError, match='is a folder, not a file') as e:
            call()
        assert str(folder) in str(e.value) and '\n' not in str(e.value)


def test_a_trainee_id_with_a_trailing_newline_is_refused(db, rng):
    with pytest.raises(ValueError, match='trainee-id'):
        store_session(db, 'ann\n', fake_report(rng))


def test_a_bag_counts_once_for_a_trainee(db, rng):
    """Scoring the same recording again (``exam report BAG`` twice, or after ``exam run
    --record``) must not add a session: three passes of one bag would master a level."""
    rep = fake_report(rng, deep=100, case='x')
    sid = store_session(db, 'ann', rep, case_level=1, bag='/bags/s1')
    for _ in range(2):
        with pytest.raises(AlreadyStored, match=f'already stored as session {sid}') as e:
            store_session(db, 'ann', rep, case_level=1, bag='/bags/s1')
        assert e.value.session == sid
    store_session(db, 'bo', rep, case_level=1, bag='/bags/s1')   # another trainee's own count
    store_session(db, 'ann', rep, case_level=1)                   # no bag: a live session
    assert len(history(db, 'ann')) == 2
    m = mastery(history(db, 'ann'), MasteryConfig({1: MasteryLevel(consecutive_sessions=3)}))
    assert m['levels'][1]['sessions'] == 2 and not m['levels'][1]['mastered']
    # a record written before the check may hold a bag twice: mastery counts it once
    dup = dict(history(db, 'ann')[0], session=99)
    m = mastery(history(db, 'ann') + [dup, dup],
                MasteryConfig({1: MasteryLevel(consecutive_sessions=3)}))
    assert m['levels'][1]['sessions'] == 2 and not m['levels'][1]['mastered']


def test_sessions_are_ordered_by_their_start_not_by_when_they_were_stored(db, rng):
    """An old bag scored after a live session takes its place by its start: the list's last
    session and its score, the history and the mastery streak follow the exams' order."""
    new = fake_report(rng, deep=100)
    new['score'], new['verdict'] = 95.0, 'pass'
    old = fake_report(rng, deep=10)
    old['score'], old['verdict'] = 40.0, 'retry'
    store_session(db, 'ann', new, started_utc='2025-03-10T10:00:00+00:00', case_level=1)
    store_session(db, 'ann', old, started_utc='2025-01-05T10:00:00+00:00', case_level=1,
                  bag='/bags/old')
    (t,) = trainees(db)
    assert (t['last_utc'], t['last_score'], t['last_verdict']) == (
        '2025-03-10T10:00:00+00:00', 95.0, 'pass')
    assert [s['score'] for s in history(db, 'ann')] == [40.0, 95.0]
    assert mastery(history(db, 'ann'))['levels'][1]['streak'] == 1   # the newest one met it


def test_corrupt_foreign_and_missing_files_are_one_line_naming_the_file(tmp_path, rng):
    bad = tmp_path / 'bad.sqlite'
    bad.write_bytes(np.random.default_rng(3).bytes(4096))
    other = tmp_path / 'other.sqlite'
    with sqlite3.connect(other) as c:
        c.execute('CREATE TABLE x (a)')
    for path, what in ((bad, 'not a readable'), (other, 'not a trainee record')):
        with pytest.raises(RecordError, match=what) as e:
            store_session(path, 'f', fake_report(rng))
        assert str(path) in str(e.value) and '\n' not in str(e.value)
    with pytest.raises(RecordError, match='no such file'):
        history(tmp_path / 'none.sqlite', 'f')
    assert not (tmp_path / 'none.sqlite').exists()    # readers create nothing
    store_session(tmp_path / 'ok.sqlite', 'f', fake_report(rng))
    with pytest.raises(RecordError, match="unknown trainee id 'g'") as e:
        history(tmp_path / 'ok.sqlite', 'g')
    assert 'ok.sqlite' in str(e.value) and 'known: f' in str(e.value)
    with pytest.raises(ValueError, match='trainee-id'):
        store_session(tmp_path / 'ok.sqlite', 'no spaces', fake_report(rng))


def test_a_locked_file_is_retried_then_named(db, rng, monkeypatch):
    store_session(db, 'gus', fake_report(rng))
    monkeypatch.setattr(rdb, 'BUSY_TIMEOUT_S', 0.05)
    monkeypatch.setattr(rdb, 'RETRIES', 3)
    holder = sqlite3.connect(db, isolation_level=None)
    holder.execute('BEGIN EXCLUSIVE')
    try:
        with pytest.raises(RecordError, match='locked') as e:
            store_session(db, 'gus', fake_report(rng))
        assert str(db) in str(e.value)
    finally:
        holder.execute('ROLLBACK')
        holder.close()
    store_session(db, 'gus', fake_report(rng))   # free again: stored
    assert len(history(db, 'gus')) == 2


def test_a_full_disk_stores_nothing_half_and_says_so(db, rng, monkeypatch):
    store_session(db, 'hal', fake_report(rng))
    with sqlite3.connect(db) as c:
        pages = c.execute('PRAGMA page_count').fetchone()[0]
    real = rdb._open

    def capped(path, create):        # the file may not grow: SQLITE_FULL, as on a full disk
        conn = real(path, create)
        conn.execute(f'PRAGMA max_page_count = {pages}')
        return conn
    monkeypatch.setattr(rdb, '_open', capped)
    big = fake_report(rng, notes=['x' * 1000] * 200)
    with pytest.raises(RecordError, match='disk full') as e:
        store_session(db, 'hal', big)
    assert str(db) in str(e.value)
    monkeypatch.setattr(rdb, '_open', real)
    assert len(history(db, 'hal')) == 1


WRITER = textwrap.dedent('''
    import sys
    import numpy as np
    sys.path.insert(0, {test_dir!r})
    from test_record import fake_report
    from haptic_anfis.record import store_session
    db, who, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    rng = np.random.default_rng(int(who[1:]))
    print('ready', flush=True)
    sys.stdin.readline()                     # every writer starts at once, on a new file
    for k in range(n):
        store_session(db, who, fake_report(rng), case_level=1)
''')


def test_concurrent_writer_processes_lose_nothing(db, tmp_path):
    script = tmp_path / 'writer.py'
    script.write_text(WRITER.format(test_dir=str(Path(__file__).parent)))
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join([str(ROOT), os.environ.get(
        'PYTHONPATH', '')])}
    n = 25
    procs = [subprocess.Popen([sys.executable, str(script), str(db), f'w{k}', str(n)], env=env,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for k in range(3)]
    for p in procs:
        assert p.stdout.readline().strip() == 'ready'
    for p in procs:
        p.stdin.write('go\n')
        p.stdin.flush()
    errs = [p.communicate(timeout=120)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], errs
    for k in range(3):
        assert len(history(db, f'w{k}')) == n
    with sqlite3.connect(db) as c:
        assert c.execute('SELECT count(*), count(DISTINCT id) FROM sessions').fetchone() == (
            3 * n, 3 * n)


KILLED = textwrap.dedent('''
    import os, signal, sys
    from haptic_anfis.record import store
    from haptic_anfis.record.db import write
    report = {report!r}
    row = store.session_row(report, source='run')
    def tx(conn):
        conn.execute("INSERT INTO trainees VALUES ('ivy', 'now')")
        cols = ', '.join(row)
        conn.execute(f"INSERT INTO sessions (trainee_id, {{cols}}) VALUES ('ivy', "
                     + ', '.join('?' for _ in row) + ')', list(row.values()))
        os.kill(os.getpid(), signal.SIGKILL)     # killed inside the session's transaction
    write(sys.argv[1], tx)
''')


def test_the_check_sees_one_state_while_another_process_creates_the_record(tmp_path):
    """The race the test above met in CI once: between the check's reads of the version and of
    the tables another process created the record (tables and version in one transaction); the
    check saw tables without a version and called it "not a trainee record"."""
    path = tmp_path / 'race.sqlite'
    with sqlite3.connect(path) as c0:
        c0.execute('PRAGMA journal_mode = WAL')   # as the record: a writer beside a reader
    conn = sqlite3.connect(str(path), isolation_level=None)
    other = sqlite3.connect(str(path), isolation_level=None)

    class Racing:   # the other process creates the record right after the version is read
        def execute(self, sql, *args):
            cur = conn.execute(sql, *args)
            if sql == 'PRAGMA user_version':
                got = cur.fetchone()
                rdb.migrate(other, path=path)
                return SimpleNamespace(fetchone=lambda: got)
            return cur
    try:
        assert rdb._check(path, Racing()) == 0   # the state before: nothing yet
        assert rdb._check(path, conn) == rdb.SCHEMA_VERSION   # and after
    finally:
        conn.close()
        other.close()


def test_a_writer_killed_mid_session_stores_nothing(db, tmp_path, rng):
    store_session(db, 'jo', fake_report(rng))
    script = tmp_path / 'killed.py'
    script.write_text(KILLED.format(report=fake_report(rng)))
    p = subprocess.run([sys.executable, str(script), str(db)], env={
        **os.environ, 'PYTHONPATH': str(ROOT)}, timeout=60)
    assert p.returncode == -signal.SIGKILL
    with pytest.raises(RecordError, match="unknown trainee id 'ivy'"):
        history(db, 'ivy')
    store_session(db, 'ivy', fake_report(rng))      # the file is not left locked
    assert len(history(db, 'ivy')) == 1 and len(history(db, 'jo')) == 1


def test_an_interrupted_exam_stores_nothing(db, rng, capsys):
    from haptic_anfis.commands._record import store_report
    args = SimpleNamespace(trainee_id='kim', db=str(db), exam_command='run', record=None)
    assert store_report(args, fake_report(rng, interrupted=True)) == 1
    assert 'interrupted' in capsys.readouterr().err and not db.exists()
    # cut off by the time limit before the trainee finished: not a whole exam either
    assert store_report(args, fake_report(rng, interrupted=False, time_limit_reached=True)) == 1
    assert 'time limit' in capsys.readouterr().err and not db.exists()
    assert store_report(args, fake_report(rng, interrupted=False)) == 0
    assert len(history(db, 'kim')) == 1


def test_delete_removes_every_row_and_every_byte_of_the_trainee(db, rng):
    secret = 'zed-private-7'
    for k in range(5):
        store_session(db, secret, fake_report(rng, case='normal', lesions=()),
                      bag=f'/b/{secret}/{k}')
    store_session(db, 'lou', fake_report(rng))
    assert delete_trainee(db, secret) == 5
    with pytest.raises(RecordError, match='unknown trainee'):
        history(db, secret)
    assert len(history(db, 'lou')) == 1
    with sqlite3.connect(db) as c:
        assert c.execute('SELECT count(*) FROM sessions WHERE trainee_id = ?', (secret,)
                         ).fetchone() == (0,)
    for f in db.parent.iterdir():    # the file and its WAL: no copy of the id left
        assert secret.encode() not in f.read_bytes(), f
    with pytest.raises(RecordError, match='unknown trainee'):
        delete_trainee(db, secret)


def test_export_csv(db, rng):
    reps = [fake_report(rng) for _ in range(3)]
    for r in reps:
        store_session(db, 'max', r, case_level=1)
    out = io.StringIO()
    assert export_csv(db, 'max', out) == 3
    rows = list(csv.DictReader(io.StringIO(out.getvalue())))
    assert [float(r['coverage_deep_pct']) for r in rows] == [r['coverage_pct']['deep']
                                                            for r in reps]
    assert [float(r['score']) for r in rows] == [r['score'] for r in reps]


def test_case_level_prefers_a_stated_level_else_count_and_size():
    T = lambda r: SimpleNamespace(radius=r)   # noqa: E731
    big, small = 0.008, 0.004
    assert case_level(SimpleNamespace(tumours=())) == 1
    assert case_level(SimpleNamespace(tumours=(T(big),))) == 1
    assert case_level(SimpleNamespace(tumours=(T(small),))) == 2
    assert case_level(SimpleNamespace(tumours=(T(big), T(big)))) == 2
    assert case_level(SimpleNamespace(tumours=(T(big), T(small)))) == 3
    assert case_level(SimpleNamespace(tumours=(T(big),) * 4)) == 3
    # a graded library's level wins, on the case or on its scene
    assert case_level(SimpleNamespace(level=4, tumours=())) == 4
    assert case_level(SimpleNamespace(name='c', scene=SimpleNamespace(level=2, tumours=()))) == 2
    with pytest.raises(ValueError, match='level'):
        case_level(SimpleNamespace(name='c', level=0))
    from haptic_anfis.cases import library
    levels = {c.name: case_level(c) for c in library().cases()}
    assert levels['default'] == 1 and levels['normal'] == 1
    assert {1, 2} <= set(levels.values())    # the first levels have cases to draw
    assert all(case_level(c) == c.level for c in library().cases() if c.level is not None)


def session(level, deep=95.0, missed=0, false_marks=0, lesions=1):
    return {'case_level': level, 'coverage_pct': {'deep': deep}, 'palpable_missed': missed,
            'false_marks': false_marks, 'lesions': lesions, 'not_palpable': []}


def test_mastery_needs_n_consecutive_sessions_meeting_the_level():
    cfg = MasteryConfig({1: MasteryLevel(consecutive_sessions=3),
                         2: MasteryLevel(consecutive_sessions=2, max_false_marks=0)})
    ok, weak = session(1), session(1, deep=80)
    assert mastery([ok, ok, weak, ok, ok], cfg)['mastered_level'] == 0   # streak broken
    m = mastery([ok, ok, weak, ok, ok, ok], cfg)
    assert m['mastered_level'] == 1 and m['next_level'] == 2
    assert m['levels'][1] == {'sessions': 6, 'met': 5, 'streak': 3, 'best_streak': 3,
                              'needed': 3, 'mastered': True, 'lesion_free': 0,
                              'lesion_free_met': 0, 'void': 0, 'cases': 6, 'false_marks': 0,
                              'false_marks_normal': 0, 'window_cases': 3,
                              'window_false_marks': 0, 'false_marks_per_case': 0.0}
    # a later weak session does not take it away; level 2 with one false mark is not met
    hist = [ok] * 3 + [weak] + [session(2, false_marks=1)] * 3
    assert mastery(hist, cfg)['mastered_level'] == 1
    m2 = mastery(hist + [session(2)] * 2, cfg)
    assert m2['mastered_level'] == 2 and m2['next_level'] == 2    # the top level stays the top
    # a palpable miss fails the level; level 2 alone without level 1 is not mastery
    assert mastery([session(1, missed=1)] * 3, cfg)['mastered_level'] == 0
    assert mastery([session(2)] * 3, cfg)['mastered_level'] == 0
    assert mastery([session(None)] * 5, cfg)['levels'][1]['sessions'] == 0


def test_mastery_config_from_exam_yaml(tmp_path):
    cfg = load_mastery_config()                     # the shipped config/exam.yaml
    assert sorted(cfg.levels) == [1, 2, 3, 4, 5]
    from haptic_anfis.exam.config import load_exam_config
    load_exam_config()                              # the scorer still reads the same file
    bad = tmp_path / 'exam.yaml'
    for doc, what in (('mastery: {levels: {1: {min_deep_coverage: 90}}}', 'fraction'),
                      ('mastery: {levels: {1: {}, 3: {}}}', '1..N'),
                      ('mastery: {levels: {1: {speed: 1}}}', 'expected keys'),
                      ('mastery: {consecutive_sessions: 0, levels: {1: {}}}', '>= 1')):
        bad.write_text(doc)
        with pytest.raises(ValueError, match=what) as e:
            load_mastery_config(bad)
        assert str(bad) in str(e.value)


def test_next_case_climbs_a_level_after_mastery(db, rng):
    from haptic_anfis.cases import library
    lib = library()
    cfg = MasteryConfig({1: MasteryLevel(consecutive_sessions=2), 2: MasteryLevel(),
                         3: MasteryLevel()})
    c, level, m = next_case(db, 'nia', lib, cfg)       # no record yet: level 1
    assert level == 1 and m['mastered_level'] == 0
    assert case_level(c) == 1 or not has_palpable_lesion(c)   # a lesion-free case: any level
    assert next_case(db, 'nia', lib, cfg)[0] == c       # reproducible from the record
    for _ in range(2):
        store_session(db, 'nia', fake_report(rng, deep=95, case=c.name), case_level=1)
    c2, level2, _ = next_case(db, 'nia', lib, cfg)
    assert level2 == 2 and (case_level(c2) == 2 or not has_palpable_lesion(c2))
    # a configured level above the hardest case in the library draws from the hardest
    one = MasteryLevel(consecutive_sessions=1)
    top = max(case_level(c) for c in lib.ready() if has_palpable_lesion(c))
    cfg_all = MasteryConfig({k: one for k in range(1, top + 2)})
    for k in range(2, top + 1):
        store_session(db, 'nia', fake_report(rng, deep=95), case_level=k)
    c3, level3, m3 = next_case(db, 'nia', lib, cfg_all)
    assert m3['next_level'] == top + 1 and level3 == top
    assert case_level(c3) == top or not has_palpable_lesion(c3)


def test_next_case_skips_a_level_without_cases_to_the_next_harder(db, rng):
    fake = [SimpleNamespace(name=f'c{k}', level=k, tumours=('lump',)) for k in (1, 2, 3, 5)]
    lib = SimpleNamespace(ready=lambda: fake)
    one = MasteryLevel(consecutive_sessions=1)
    cfg = MasteryConfig({k: one for k in range(1, 6)})
    for k in (1, 2, 3):
        store_session(db, 'ola', fake_report(rng, deep=95), case_level=k)
    c, level, m = next_case(db, 'ola', lib, cfg)
    assert m['next_level'] == 4 and level == 5 and c.name == 'c5'


def test_next_case_prefers_graded_cases_of_the_level(db):
    old = SimpleNamespace(name='coarse', level=None, tumours=(SimpleNamespace(radius=0.01),))   # level 1: one lesion
    new = SimpleNamespace(name='graded', level=1, tumours=(SimpleNamespace(radius=0.01),))
    lib = SimpleNamespace(ready=lambda: [old, new])
    for _ in range(3):
        c, level, _ = next_case(db, 'pia', lib, MasteryConfig({1: MasteryLevel()}))
        assert level == 1 and c.name == 'graded'


def test_trainees_cli(db, tmp_path, rng, capsys):
    for k in range(4):
        store_session(db, 'oz', fake_report(rng, deep=60 + 10 * k), case_level=1)
    assert main(['trainees', '--db', str(db), 'list']) == 0
    assert 'oz' in capsys.readouterr().out
    assert main(['trainees', 'show', 'oz', '--db', str(db)]) == 0
    out = capsys.readouterr().out
    assert 'mastered level' in out and out.count('\n') >= 6
    png = tmp_path / 'curve.png'
    assert main(['trainees', '--db', str(db), 'progress', 'oz', '--json', '--figure',
                 str(png)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc['sessions']) == 4 and doc['mastery']['mastered_level'] == 0
    assert png.stat().st_size > 10_000
    assert main(['trainees', '--db', str(db), 'export', 'oz', '--csv']) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 5
    assert main(['trainees', 'list', '--db', str(db)]) == 0   # --db after the action too
    assert 'oz' in capsys.readouterr().out
    # a failed export (a mistyped id) leaves an earlier export as it was
    old = tmp_path / 'oz.csv'
    old.write_text('an earlier export\n')
    assert main(['trainees', '--db', str(db), 'export', 'o2', '--csv', '-o', str(old)]) == 1
    assert "unknown trainee id 'o2'" in capsys.readouterr().err
    assert old.read_text() == 'an earlier export\n'
    assert main(['trainees', '--db', str(db), 'export', 'oz', '--csv', '-o', str(old)]) == 0
    assert len(old.read_text().splitlines()) == 5
    assert '4 session(s) of oz written' in capsys.readouterr().err
    assert main(['trainees', '--db', str(db), 'show', 'nobody']) == 1
    err = capsys.readouterr().err
    assert "unknown trainee id 'nobody'" in err and str(db) in err and err.count('\n') == 1
    assert main(['trainees', '--db', str(db), 'delete', 'oz']) == 0
    assert main(['trainees', '--db', str(db), 'list']) == 0
    assert 'no trainee' in capsys.readouterr().out


def pressing_bag(path: Path, t0_ns: int = 100_000_000_000) -> Path:
    """A 2 s bag of /contact samples pressing 10 mm deep along a line (built as test_exam_run
    builds its hover bag), its first message received at ``t0_ns``."""
    from haptic_anfis.bag import typestore
    from haptic_anfis.bag.writer import BagWriter
    from haptic_anfis import interfaces as ifc
    ts = typestore()
    T, H = ts.types['builtin_interfaces/msg/Time'], ts.types['std_msgs/msg/Header']
    JS = ts.types['sensor_msgs/msg/JointState']
    with BagWriter(path) as w:
        w.add_topic('/contact', JS.__msgtype__)
        for k in range(200):
            v = np.zeros(len(ifc.CONTACT_FIELDS))
            v[0:3] = (0.045, 0.0005 * (k - 100), 0.0)
            v[ifc.I_DEPTH], v[ifc.I_IN_CONTACT] = 0.01, 1.0
            js = JS(H(T(100 + k // 100, (k % 100) * 10_000_000), 'tissue'),
                    list(ifc.CONTACT_FIELDS), v, np.zeros(0), np.zeros(0))
            w.write('/contact', ts.serialize_cdr(js, JS.__msgtype__), t0_ns + k * 10**7)
    return path


@pytest.mark.ros
def test_exam_report_stores_the_full_report_and_a_bad_record_still_prints_it(db, tmp_path,
                                                                             capfd):
    bag = pressing_bag(tmp_path / 'bag')
    # a bag named by its MCAP file is stored as its folder (one recording, one path)
    other = tmp_path / 'other.sqlite'
    assert main(['exam', 'report', str(bag / 'bag.mcap'), '--trainee-id', 'pat', '--db',
                 str(other)]) == 0
    assert [h['bag'] for h in history(other, 'pat')] == [str(bag.resolve())]
    capfd.readouterr()
    assert main(['exam', 'report', str(bag), '--trainee-id', 'pat', '--db', str(db),
                 '--json']) == 0
    r = json.loads(capfd.readouterr().out.strip().splitlines()[-1])
    (s,) = history(db, 'pat', full=True)
    assert s['report'] == r and s['source'] == 'bag' and s['bag'] == str(bag.resolve())
    from haptic_anfis.cases import library
    assert s['case'] == 'default' and s['case_level'] == case_level(library().get('default'))
    assert s['coverage_pct'] == r['coverage_pct'] and s['misses'] == r['misses']
    # a corrupt record: the report is printed all the same, one line names the file, exit 1
    bad = tmp_path / 'bad.sqlite'
    bad.write_bytes(b'not sqlite' * 500)
    assert main(['exam', 'report', str(bag), '--trainee-id', 'pat', '--db', str(bad),
                 '--json']) == 1
    out, err = capfd.readouterr()
    assert json.loads(out.strip().splitlines()[-1])['coverage_pct'] == r['coverage_pct']
    assert 'coverage ' in out and str(bad) in err and len(err.strip().splitlines()) == 1
    # the same bag scored again: the report is printed, the record keeps its first session
    assert main(['exam', 'report', str(bag), '--trainee-id', 'pat', '--db', str(db)]) == 0
    out, err = capfd.readouterr()
    assert f'already stored as session {s["session"]}' in out and not err
    assert len(history(db, 'pat')) == 1
    # its MCAP file named instead of its folder: the same recording
    assert main(['exam', 'report', str(bag / 'bag.mcap'), '--trainee-id', 'pat', '--db',
                 str(db)]) == 0
    out, err = capfd.readouterr()
    assert f'already stored as session {s["session"]}' in out and not err
    # the bag deleted and a new session recorded to its path: a session of its own
    shutil.rmtree(bag)
    pressing_bag(bag, t0_ns=200_000_000_000)
    assert main(['exam', 'report', str(bag), '--trainee-id', 'pat', '--db', str(db)]) == 0
    out, err = capfd.readouterr()
    assert 'stored' in out and 'already' not in out and not err
    assert [h['bag_start_ns'] for h in history(db, 'pat')] == [100_000_000_000, 200_000_000_000]
    # a bad id is refused before the exam, and --next needs an id
    assert main(['exam', 'report', str(bag), '--trainee-id', 'a b']) == 1
    assert 'trainee-id' in capfd.readouterr().err
    assert main(['exam', 'run', '--next']) == 1
    assert '--next needs --trainee-id' in capfd.readouterr().err


def test_a_blind_case_goes_to_the_nodes_as_a_seed_that_draws_it():
    from haptic_anfis.cases import library
    from haptic_anfis.commands._record import case_parameter
    lib = library()
    c = lib.ready()[-1]     # one case: each draw re-reads the library (~0.1 s)
    name, seed = case_parameter(SimpleNamespace(blind=True), c)
    assert name == 'random_case_seed' and lib.random(seed).name == c.name
    assert case_parameter(SimpleNamespace(), c) == ('case', c.name)


def test_the_page_shows_a_bad_trainee_id_or_record_as_an_error_row(db, rng):
    """The browser view's history call: what the instructor typed on the page is never a
    traceback in the node."""
    from haptic_anfis.view.app import trainee_history
    store_session(db, 'ann', fake_report(rng))
    assert len(trainee_history('ann', db)) == 1
    for tid, what in (('Jane Doe', 'trainee-id'), ('nobody', 'unknown trainee')):
        (row,) = trainee_history(tid, db)
        assert what in row['error']
