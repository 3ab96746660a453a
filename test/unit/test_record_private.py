"""The trainee record is private (0600 in a 0700 folder) and honest (a full disk is said as a full
disk, and reads still work on it); trainee ids are letters of any alphabet, as documented."""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from haptic_anfis.record import RecordError, check_trainee_id, store_session, trainees

REPORT = {'coverage_pct': {'light': 10.0, 'medium': 5.0, 'deep': 1.0}, 'hits': 0, 'misses': 0,
          'false_marks': 0, 'score': 12.5, 'verdict': 'needs practice', 'duration_s': 60.0,
          'lesions': []}
ROOT = Path(__file__).resolve().parents[2]   # the checkout


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


def test_a_new_record_is_0600_in_a_new_0700_folder(tmp_path):
    old = os.umask(0o022)   # the usual umask, under which SQLite alone made the file 0644
    try:
        db = tmp_path / 'made' / 'here' / 'trainees.sqlite'
        store_session(db, 'ann', REPORT)
    finally:
        os.umask(old)
    assert _mode(db) == 0o600 and _mode(db.parent) == 0o700
    for side in (Path(f'{db}-wal'), Path(f'{db}-shm')):
        assert not side.exists() or _mode(side) == 0o600


def test_an_older_readable_record_is_narrowed_when_opened_and_a_chosen_folder_is_left(tmp_path):
    db = tmp_path / 'trainees.sqlite'
    store_session(db, 'ann', REPORT)
    os.chmod(db, 0o644)
    os.chmod(tmp_path, 0o755)
    assert [t['id'] for t in trainees(db)] == ['ann']   # a read narrows it too
    assert _mode(db) == 0o600 and _mode(tmp_path) == 0o755


def test_the_default_folder_is_narrowed_to_0700(tmp_path, monkeypatch):
    monkeypatch.setenv('XDG_DATA_HOME', str(tmp_path))
    monkeypatch.delenv('HAPTIC_ANFIS_DB', raising=False)
    folder = tmp_path / 'haptic_anfis'
    folder.mkdir(mode=0o755)
    os.chmod(folder, 0o755)
    store_session(None, 'ann', REPORT)
    assert _mode(folder) == 0o700 and _mode(folder / 'trainees.sqlite') == 0o600


@pytest.mark.parametrize('tid', ['t017', 'Zoë', 'Łukasz', '明', 'ana.m+1@x-y', 'ß' * 64])
def test_trainee_ids_are_letters_of_any_alphabet_digits_and_punctuation(tid):
    assert check_trainee_id(tid) == tid


@pytest.mark.parametrize('tid', ['', 'a b', '<img src=x>', 'ann\n', '.ann', 'x' * 65,
                                 'Zoe\u0308', 'ann\u202e', 'a/b'])
def test_other_trainee_ids_are_refused_in_one_line(tid):
    with pytest.raises(ValueError, match='--trainee-id') as e:
        check_trainee_id(tid)
    assert '\n' not in str(e.value).replace('\\n', '')


FULL_DISK = r'''
import json, os, sys
from haptic_anfis.record import RecordError, store_session, trainees
REPORT = json.loads(sys.argv[2])
d = sys.argv[1]
db = os.path.join(d, 'rec', 'trainees.sqlite')
store_session(db, 'ann', REPORT)
fd = os.open(os.path.join(d, 'filler'), os.O_WRONLY | os.O_CREAT)
try:
    while True:
        os.write(fd, b'\0' * 4096)
except OSError:
    pass
os.close(fd)
try:
    store_session(db, 'ann', dict(REPORT, notes=['x' * 20000]))
    print('stored')
except RecordError as exc:
    print('store:', exc)
print('list:', [(t['id'], t['sessions']) for t in trainees(db)])
'''


def test_a_full_disk_is_said_as_a_full_disk_and_the_record_still_reads(tmp_path):
    """On a 512 KiB tmpfs (its own mount namespace: ``unshare -rm``) filled up after one stored
    session: storing another says the disk is full in one line; listing still works."""
    if shutil.which('unshare') is None:
        pytest.skip('no unshare(1) to mount a small filesystem')
    mnt = tmp_path / 'small'
    mnt.mkdir()
    script = tmp_path / 'full.py'
    script.write_text(FULL_DISK)
    p = subprocess.run(['unshare', '-rm', 'sh', '-c',
                        f'mount -t tmpfs -o size=512k tmpfs {mnt} && exec {sys.executable} '
                        f'{script} {mnt} \'{json.dumps(REPORT)}\''], cwd=ROOT, env={**os.environ, 'PYTHONPATH': str(ROOT)},
                       capture_output=True, text=True, timeout=120)
    if p.returncode != 0 and 'mount' in p.stderr and 'Traceback' not in p.stderr:
        pytest.skip(f'cannot mount a tmpfs here: {p.stderr.strip()}')
    assert p.returncode == 0, p.stderr
    store, listed = p.stdout.strip().splitlines()
    assert store.startswith('store: trainee record ') and 'disk full (0 bytes free on its filesystem)' in store
    assert listed == "list: [('ann', 1)]"

