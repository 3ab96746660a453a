"""Files an exam writes for another process to read, written whole or not at all (no ROS).

The examiner runs in a process of its own and writes its report when stopped; ``exam run``
reads what it wrote. A file half written when it is read (a loaded machine, a reader that did
not wait) must never pass for a whole one: each is written under a temporary name in the same
folder and renamed into place (a rename within one file system is atomic on POSIX), so the
final name appears only once the content is complete.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import IO, Callable

__all__ = ['write_atomic', 'write_text_atomic']


def write_atomic(path: str | os.PathLike, write: Callable[[IO[bytes]], None]) -> Path:
    """Call ``write(f)`` on a temporary file beside ``path``, flush it to disk and rename it to
    ``path``; returns ``path``. On any error the temporary file is removed and ``path`` is left
    as it was."""
    path = Path(path)
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.part')
    try:
        with open(tmp, 'wb') as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """:func:`write_atomic` of ``text`` (UTF-8)."""
    return write_atomic(path, lambda f: f.write(text.encode()))
