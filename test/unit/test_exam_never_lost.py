"""An exam never lost: the examiner's files appear whole or not at all, and the exam waits for
the examiner to finish writing instead of killing it after a short grace."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from haptic_anfis.exam.files import write_atomic, write_text_atomic
from haptic_anfis.session import one_process
from haptic_anfis.session.one_process import finish_process

#: a stand-in examiner: once asked to stop (SIGINT) it takes ``delay`` s to write its report
SLOW_WRITER = textwrap.dedent('''
    import signal, sys, time
    from haptic_anfis.exam.files import write_text_atomic
    out, delay = sys.argv[1], float(sys.argv[2])
    try:
        print('up', flush=True)   # inside the try: a SIGINT right after it is handled too
        time.sleep(120)
    except KeyboardInterrupt:
        time.sleep(delay)   # a loaded machine: the figure and the samples take their time
        write_text_atomic(out, '{"score": 1}')
''')


def slow_writer(tmp_path, delay: float) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, '-c', SLOW_WRITER, str(tmp_path / 'report.json'),
                          str(delay)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == 'up'   # its SIGINT handler is in place
    return p


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
def test_the_exam_waits_for_a_slow_examiner_and_says_so(tmp_path, monkeypatch):
    monkeypatch.setattr(one_process, 'FINISH_SAY_S', 0.5)
    p = slow_writer(tmp_path, 2.5)   # 2.5 s: past the lines' period, within the limit
    said = []
    assert finish_process(p, 'examiner', 60.0, say=said.append) == 0
    assert (tmp_path / 'report.json').read_text() == '{"score": 1}'
    assert len(said) >= 3 and all(s.startswith('examiner: finishing its output') for s in said)


def test_an_examiner_still_writing_at_the_limit_gets_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr(one_process, 'FINISH_SAY_S', 0.5)
    p = slow_writer(tmp_path, 30.0)
    said = []
    try:
        assert finish_process(p, 'examiner', 1.2, say=said.append) is None
        assert said[-1] == 'examiner: still writing its output after 1.2 s; stopping it'
        assert not (tmp_path / 'report.json').exists()
    finally:
        p.kill()
        p.wait()


def test_atomic_files_are_whole_or_absent(tmp_path):
    path = tmp_path / 'samples.npz'
    write_atomic(path, lambda f: np.savez(f, a=np.arange(3.0)))
    with np.load(path) as z:
        assert z['a'].tolist() == [0.0, 1.0, 2.0]

    def broken(f):
        f.write(b'half a file')
        raise OSError('disk full')
    with pytest.raises(OSError, match='disk full'):
        write_atomic(path, broken)
    with np.load(path) as z:   # the old file stands, no temporary left behind
        assert z['a'].tolist() == [0.0, 1.0, 2.0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ['samples.npz']
    write_text_atomic(tmp_path / 'report.json', '{}')
    assert (tmp_path / 'report.json').read_text() == '{}'
