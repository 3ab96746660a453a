"""The trainee record's SQLite file: where it lives, opening it, its schema and migrations.

One file (default ``$XDG_DATA_HOME/haptic_anfis/trainees.sqlite``, else
``~/.local/share/haptic_anfis/trainees.sqlite``; the environment variable ``HAPTIC_ANFIS_DB`` or
``--db PATH`` chooses another). Opened in WAL mode (readers never block the one writer) with a
busy timeout, every write in ONE ``BEGIN IMMEDIATE`` transaction (it takes the write lock first,
so the busy handler applies and a reader-turned-writer never dead-locks), retried while the file
is busy. ``PRAGMA user_version`` is the schema version: an older file is migrated in place, a
newer one refused. ``PRAGMA application_id`` marks the file as ours.

Every failure (not a database, corrupt, locked past the retries, disk full, newer schema) is a
:class:`RecordError` whose message is one line naming the file. Pure Python (``sqlite3``), no ROS.

Private: the record holds people's results, so the file is created 0600 (its WAL and shared-memory
files take its mode: SQLite gives them the database's), and a folder the record creates is 0700,
as is the default folder (``.../haptic_anfis``) however it was made. A file that already exists
and belongs to this user is narrowed to 0600 when it is opened (a record made before this rule
was 0644); a folder the user chose (``--db``) is left as it is: it is theirs.

A full disk: SQLite says "database or disk is full", or, opening a WAL file whose shared-memory
index cannot be made, "disk I/O error"; either, with the file's filesystem out of space, is
said as a full disk. Reading (``trainees list``) still works on a full disk: when the shared-memory
index cannot be made and no write-ahead log is pending, the file is read as an immutable one
(``immutable=1``: no lock, no index; nothing can be written then anyway).
"""
from __future__ import annotations

import errno
import os
import sqlite3
import stat
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TypeVar
from urllib.parse import quote

from ..errors import HapticAnfisError

__all__ = ['APPLICATION_ID', 'DB_ENV', 'RecordError', 'SCHEMA_VERSION', 'connect',
           'default_db_path', 'migrate', 'resolve_db_path', 'write']

#: the environment variable naming the record file
DB_ENV = 'HAPTIC_ANFIS_DB'
#: ``PRAGMA application_id`` of a trainee record ('HAnR')
APPLICATION_ID = 0x48416E52
#: [s] SQLite's own wait for a lock, per attempt
BUSY_TIMEOUT_S = 5.0
#: attempts of one transaction while the file stays busy (``BUSY_TIMEOUT_S`` each)
RETRIES = 6
#: [bytes] an I/O error with less than this free on the record's filesystem is a full disk (the
#: shared-memory index SQLite makes at the first open of a WAL file is 32 KiB)
FULL_BELOW = 64 * 1024

T = TypeVar('T')


class RecordError(HapticAnfisError, ValueError):
    """The trainee record cannot be used: one line naming the file and what is wrong."""


# --- schema -------------------------------------------------------------------------------------
# MIGRATIONS[k] takes a file from user_version k to k + 1. Never edit a released step: add one.
_V1 = """
CREATE TABLE trainees (
    id          TEXT PRIMARY KEY,
    created_utc TEXT NOT NULL
);
CREATE TABLE sessions (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    trainee_id     TEXT NOT NULL REFERENCES trainees(id) ON DELETE CASCADE,
    started_utc    TEXT NOT NULL,
    stored_utc     TEXT NOT NULL,
    source         TEXT NOT NULL,
    case_name      TEXT,
    case_level     INTEGER,
    bag_path       TEXT,
    coverage_light REAL NOT NULL,
    coverage_medium REAL NOT NULL,
    coverage_deep  REAL NOT NULL,
    pattern        TEXT,
    lesions        INTEGER NOT NULL,
    hits           INTEGER NOT NULL,
    misses         INTEGER NOT NULL,
    false_marks    INTEGER NOT NULL,
    score          REAL NOT NULL,
    verdict        TEXT NOT NULL,
    duration_s     REAL NOT NULL,
    contact_s      REAL,
    report_json    TEXT NOT NULL
);
CREATE INDEX sessions_by_trainee ON sessions(trainee_id, id);
"""
# v2: lesions the FE grades not palpable (the graded library): a miss of one is not held
# against the trainee; and the misses that count.
_V2 = """
ALTER TABLE sessions ADD COLUMN not_palpable TEXT NOT NULL DEFAULT '[]';
ALTER TABLE sessions ADD COLUMN palpable_missed INTEGER;
UPDATE sessions SET palpable_missed = misses;
"""
# v3: which recording a bag path held (its first message's time [ns]): an instructor who records
# to the same path again (after deleting the old bag) makes a new session, not a repeat of one.
_V3 = """
ALTER TABLE sessions ADD COLUMN bag_start_ns INTEGER;
"""
# v4: a trainee's own stiffness-discrimination threshold (`haptic-anfis threshold`), and what
# predicts finding lumps: search time per area, time at each pressure level, the force when
# palpating vs searching (the session's report holds the details; these are its headline figures).
_V4 = """
CREATE TABLE thresholds (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    trainee_id    TEXT NOT NULL REFERENCES trainees(id) ON DELETE CASCADE,
    measured_utc  TEXT NOT NULL,
    threshold_pct REAL NOT NULL,
    trials        INTEGER NOT NULL,
    device        TEXT NOT NULL,
    details_json  TEXT NOT NULL
);
CREATE INDEX thresholds_by_trainee ON thresholds(trainee_id, id);
ALTER TABLE sessions ADD COLUMN time_at_level_json TEXT;
ALTER TABLE sessions ADD COLUMN area_time_json TEXT;
ALTER TABLE sessions ADD COLUMN force_palpating_n REAL;
ALTER TABLE sessions ADD COLUMN force_searching_n REAL;
ALTER TABLE sessions ADD COLUMN lesion_levels_json TEXT
"""
# v5: a session whose haptic loop fell behind is void (haptic_anfis.exam.void): why, else NULL;
# mastery leaves it out. A blind session (exam run --next): its case is named to the instructor
# only, never in what the trainee sees of the record.
_V5 = """
ALTER TABLE sessions ADD COLUMN void_reason TEXT;
ALTER TABLE sessions ADD COLUMN blind INTEGER NOT NULL DEFAULT 0;
"""
# v6: specificity: of a session's false marks, those on a normal structure (a normal lobule or a
# rib of a nodular case) -- the rest fell elsewhere. Taken from the stored report where it says
# (a report scored since false marks name the nodule or rib); NULL (not known) before that.
_V6 = """
ALTER TABLE sessions ADD COLUMN false_marks_normal INTEGER;
UPDATE sessions SET false_marks_normal = CASE WHEN json_valid(report_json)
    THEN json_extract(report_json, '$.false_marks_normal') END
"""
MIGRATIONS: tuple[str, ...] = (_V1, _V2, _V3, _V4, _V5, _V6)
SCHEMA_VERSION = len(MIGRATIONS)


def default_db_path() -> Path:
    """``$XDG_DATA_HOME/haptic_anfis/trainees.sqlite`` (``~/.local/share`` when unset)."""
    base = os.environ.get('XDG_DATA_HOME') or str(Path.home() / '.local' / 'share')
    return Path(base) / 'haptic_anfis' / 'trainees.sqlite'


def resolve_db_path(db: str | os.PathLike | None = None) -> Path:
    """``db`` if given, else ``$HAPTIC_ANFIS_DB``, else :func:`default_db_path`."""
    if db:
        return Path(db)
    env = os.environ.get(DB_ENV)
    return Path(env) if env else default_db_path()


def _free_bytes(path: Path) -> int | None:
    """Bytes this user may still write on the filesystem of ``path`` (its nearest existing
    folder); None when it cannot be asked."""
    for p in (path, *path.parents):
        if p.exists():
            try:
                st = os.statvfs(p)
            except OSError:
                return None
            return st.f_bavail * st.f_frsize
    return None


def _disk_full(path: Path, exc: BaseException) -> bool:
    """Whether ``exc`` means the record's filesystem is full: ENOSPC / EDQUOT, SQLite's
    SQLITE_FULL, or an SQLite I/O error with (almost) no space left."""
    if isinstance(exc, OSError):
        return exc.errno in (errno.ENOSPC, errno.EDQUOT)
    name = getattr(exc, 'sqlite_errorname', '') or ''
    if name == 'SQLITE_FULL' or 'disk is full' in str(exc).lower():
        return True
    if name.startswith('SQLITE_IOERR'):
        free = _free_bytes(path)
        return free is not None and free < FULL_BELOW
    return False


def _fail(path: Path, exc: BaseException) -> RecordError:
    msg = str(exc)
    low = msg.lower()
    if _disk_full(path, exc):
        free = _free_bytes(path)
        why = ('disk full (' + (f'{free} bytes free on its filesystem' if free is not None
                                and free < FULL_BELOW else msg)
               + '): nothing is written to a full disk; free some space and try again')
    elif 'locked' in low or 'busy' in low:
        why = (f'locked by another process (still busy after {RETRIES} tries of '
               f'{BUSY_TIMEOUT_S:g} s)')
    elif 'not a database' in low or 'malformed' in low or 'corrupt' in low:
        why = f'not a readable SQLite trainee record ({msg})'
    elif 'readonly' in low or 'unable to open' in low or 'permission' in low:
        why = f'cannot be written ({msg})'
    else:
        why = msg
    return RecordError(f'trainee record {str(path)!r}: {why}')


def _busy(exc: sqlite3.Error) -> bool:
    return isinstance(exc, sqlite3.OperationalError) and (
        'locked' in str(exc).lower() or 'busy' in str(exc).lower())


def _retrying(path: Path, fn: Callable[[], T]) -> T:
    """``fn()``, again while SQLite says the file is busy; any sqlite/OS error -> RecordError."""
    for attempt in range(RETRIES):
        try:
            return fn()
        except sqlite3.Error as exc:
            if _busy(exc) and attempt < RETRIES - 1:
                time.sleep(0.05 * (attempt + 1))
                continue
            raise _fail(path, exc) from None
        except OSError as exc:
            raise _fail(path, exc) from None
    raise AssertionError('unreachable')


def _open(path: Path, create: bool) -> sqlite3.Connection:
    if path.exists() and not path.is_file():
        raise RecordError(f'trainee record {str(path)!r}: is a folder, not a file (expected the '
                          'record\'s SQLite file, e.g. <folder>/trainees.sqlite)')
    if not create and not path.is_file():
        raise RecordError(f'trainee record {str(path)!r}: no such file (nothing stored yet)')
    try:
        if create:
            _private_folder(path.parent)
            _private_file(path)
        _narrow(path)
    except OSError as exc:
        raise _fail(path, exc) from None
    # isolation_level=None: we issue BEGIN / COMMIT ourselves (one transaction per session)
    conn = sqlite3.connect(str(path), timeout=BUSY_TIMEOUT_S, isolation_level=None)
    try:
        conn.execute(f'PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}')
        version = _check(path, conn)   # before anything that changes the file: refused = untouched
        if conn.execute('PRAGMA journal_mode').fetchone()[0].lower() != 'wal':
            conn.execute('PRAGMA journal_mode = WAL')
        conn.execute('PRAGMA foreign_keys = ON')
        conn.execute('PRAGMA synchronous = NORMAL')   # WAL: durable at checkpoints, never corrupt
        if version < SCHEMA_VERSION:
            migrate(conn, path=path)
    except BaseException:
        conn.close()
        raise
    return conn


def _private_folder(folder: Path) -> None:
    """Make ``folder`` 0700 if missing; narrow the default record folder to 0700 as well."""
    try:   # no exists() check first: writer processes starting together race to create it
        folder.mkdir(parents=True, mode=0o700)
    except FileExistsError:
        if folder == default_db_path().parent:
            _narrow(folder, 0o700)
        return
    os.chmod(folder, 0o700)   # mkdir's mode passes through the umask


def _private_file(path: Path) -> None:
    """Create the empty record file 0600 before SQLite opens it (SQLite would make it 0644;
    an empty file is an empty database to it)."""
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except FileExistsError:
        pass


def _narrow(path: Path, mode: int = 0o600) -> None:
    """Take away group and other access to ``path`` (and its ``-wal`` / ``-shm`` files) if it
    belongs to this user and grants any; another user's file is left as it is, and so is one on
    a read-only filesystem (it can still be read)."""
    for p in (path, Path(f'{path}-wal'), Path(f'{path}-shm')):
        try:
            st = p.stat()
        except FileNotFoundError:
            continue
        if st.st_uid == os.getuid() and stat.S_IMODE(st.st_mode) & 0o077:
            try:
                os.chmod(p, mode)
            except OSError:   # a read-only filesystem: it cannot be narrowed, nor written
                pass


def _check(path: Path, conn: sqlite3.Connection) -> int:
    """The file's schema version, read without writing; RecordError for a newer schema or a
    database that is not a trainee record (someone else's file is left as it was).

    One read transaction: its reads see one state of the file. Read one by one, a process that
    created the record between them (its tables and version in one transaction) made this one
    see its tables without a version: "not a trainee record" (the concurrent-writers test)."""
    conn.execute('BEGIN')   # deferred: no lock is taken for writing, nothing is written
    try:
        version = _check_in_transaction(path, conn)
    except BaseException:
        try:
            conn.execute('ROLLBACK')
        except sqlite3.OperationalError:   # SQLite ended it itself (a full disk): the cause
            pass                           # is the error raised, not "no transaction"
        raise
    conn.execute('COMMIT')
    return version


def _check_in_transaction(path: Path, conn: sqlite3.Connection) -> int:
    app = conn.execute('PRAGMA application_id').fetchone()[0]
    version = conn.execute('PRAGMA user_version').fetchone()[0]
    if version > SCHEMA_VERSION:
        raise RecordError(f'trainee record {str(path)!r}: schema version {version} is newer than '
                          f'this haptic_anfis understands ({SCHEMA_VERSION}); upgrade haptic_anfis '
                          'to use it (the file is left untouched)')
    if app not in (0, APPLICATION_ID):
        raise RecordError(f'trainee record {str(path)!r}: not a trainee record (application_id '
                          f'{app:#x}, expected {APPLICATION_ID:#x})')
    if version == 0:
        _no_foreign_tables(path, conn)
    return version


def _no_foreign_tables(path: Path | None, conn: sqlite3.Connection) -> None:
    """RecordError for a version-0 file that already has tables (someone else's database)."""
    tables = conn.execute("SELECT count(*) FROM sqlite_master WHERE type = 'table'").fetchone()[0]
    if tables:
        raise RecordError(f'trainee record {str(path)!r}: not a trainee record (it has '
                          f'{tables} table(s) but no schema version)')


def migrate(conn: sqlite3.Connection, to: int = SCHEMA_VERSION,
            path: Path | None = None) -> int:
    """Bring the file up to schema version ``to`` in one transaction; returns the old version.

    Raises:
        RecordError: a version-0 file that already has tables (someone else's database).
    """
    conn.execute('BEGIN IMMEDIATE')
    try:
        old = conn.execute('PRAGMA user_version').fetchone()[0]   # again, under the write lock
        if old == 0:
            _no_foreign_tables(path, conn)
        for step in MIGRATIONS[old:to]:
            for stmt in filter(str.strip, step.split(';')):
                conn.execute(stmt)
        conn.execute(f'PRAGMA user_version = {int(max(old, to))}')
        conn.execute(f'PRAGMA application_id = {APPLICATION_ID}')
        conn.execute('COMMIT')
        return old
    except BaseException:
        if conn.in_transaction:   # SQLite rolls back itself on some errors (a full disk)
            conn.execute('ROLLBACK')
        raise


@contextmanager
def connect(db: str | os.PathLike | None = None, create: bool = False
            ) -> Iterator[sqlite3.Connection]:
    """An open, migrated connection to the record (``db`` as in :func:`resolve_db_path`).

    ``create=False`` (readers): a missing file is a RecordError, nothing is created.

    Raises:
        RecordError: missing / corrupt / locked / newer-schema / full file, naming it.
    """
    path = resolve_db_path(db)
    try:
        conn = _retrying(path, lambda: _open(path, create))
    except RecordError:
        conn = None if create else _open_immutable(path)
        if conn is None:
            raise
    try:
        yield conn
    except sqlite3.Error as exc:
        raise _fail(path, exc) from None
    finally:
        conn.close()


def _open_immutable(path: Path) -> sqlite3.Connection | None:
    """A read-only connection to a record on a full disk (SQLite could not make its
    shared-memory index): ``immutable=1`` needs no index and no lock. None when the disk is not
    full, a write-ahead log is pending (its rows would be missed) or the schema is not current
    (it could not be migrated)."""
    wal = Path(f'{path}-wal')
    if not path.is_file() or (wal.exists() and wal.stat().st_size > 0):
        return None
    free = _free_bytes(path)
    if free is None or free >= FULL_BELOW:
        return None
    conn = sqlite3.connect(f'file:{quote(str(path.resolve()))}?immutable=1', uri=True,
                           isolation_level=None)
    try:
        if _check(path, conn) != SCHEMA_VERSION:
            conn.close()
            return None
    except (sqlite3.Error, RecordError):
        conn.close()
        return None
    return conn


def write(db: str | os.PathLike | None, fn: Callable[[sqlite3.Connection], T]) -> T:
    """Run ``fn(conn)`` in ONE ``BEGIN IMMEDIATE`` transaction on the record (created if
    missing), committed whole or not at all; retried while another process holds the lock."""
    path = resolve_db_path(db)

    def attempt():
        conn = _open(path, create=True)
        try:
            conn.execute('BEGIN IMMEDIATE')
            try:
                out = fn(conn)
                conn.execute('COMMIT')
            except BaseException:
                if conn.in_transaction:
                    conn.execute('ROLLBACK')
                raise
            return out
        finally:
            conn.close()
    return _retrying(path, attempt)
