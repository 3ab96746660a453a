"""A rosbag2 writer (MCAP storage, metadata version 9) fed from a queue by its own thread.

Producers (subscription callbacks, a 1 kHz loop) only append ``(topic, time, serialized bytes)`` to
an unbounded ``queue.SimpleQueue`` (a C call, never blocks); the writer thread does all file work.
Crash safety: the pending MCAP chunk is closed and flushed to the OS at least every
``flush_period`` seconds (and once it holds ``chunk_size`` bytes), so a ``kill -9`` loses at most
the last ``flush_period`` of messages plus what is still queued; the file left behind has no
summary and no ``metadata.yaml`` — :func:`haptic_anfis.bag.recover_bag` rebuilds both.

A failing disk (full, a file-size limit, an I/O error): the writer thread catches the error at
once, seals the bag (cut back to the last whole chunk, closed, metadata.yaml: ``bag info`` opens it;
see :meth:`.segment.Segment.seal`) and calls ``on_error`` with a one-line message. With a
``fallback_dir`` it then continues in a new bag of the same name there, starting with the messages
of the chunk that failed, so nothing received is lost; without one it stops (``failed``), and
later messages are counted in ``lost``.
"""
from __future__ import annotations

import queue
import threading
import time
from pathlib import Path
from typing import Callable

from .errors import BagError
from .segment import COMPRESSIONS, Segment, compressor
from .topics import typestore

_ADD = object()
_CUSTOM = object()


class BagWriter:
    """Write a rosbag2 bag from any thread without blocking it.

    Args:
        path: bag directory to create (must not exist; parents are created).
        flush_period: close + flush the pending chunk at least this often [s].
        chunk_size: close the pending chunk once it holds this many bytes.
        max_queue: messages allowed to wait for the writer thread; beyond that :meth:`write`
            drops the message, counts it in ``dropped`` and returns False.
        custom_data: strings stored in metadata.yaml's ``custom_data``.
        compression: MCAP chunk compression, one of :data:`COMPRESSIONS` ('none', 'zstd' at
            level 1, 'lz4'); see the README for the measured size and cost.
        fallback_dir: where to continue (a new bag of the same name) if writing ``path`` fails;
            None: stop recording at the failure.
        on_error: called once per failure, from the writer thread, with a one-line message.
    """

    def __init__(self, path: str | Path, *, flush_period: float = 0.5, chunk_size: int = 256 * 1024,
                 max_queue: int = 200_000, custom_data: dict[str, str] | None = None,
                 compression: str = 'none', fallback_dir: str | Path | None = None,
                 on_error: Callable[[str], None] | None = None):
        self.path = Path(path)
        if not flush_period > 0 or chunk_size <= 0 or max_queue <= 0:
            raise BagError(f'{self.path}: flush_period, chunk_size and max_queue must be > 0')
        compressor(compression)  # a clear error for an unknown name, before creating anything
        self.flush_period, self.chunk_size, self.max_queue = flush_period, chunk_size, max_queue
        self.compression = compression
        self.custom_data = {k: str(v) for k, v in (custom_data or {}).items()}
        self.fallback_dir = Path(fallback_dir) if fallback_dir else None
        self.on_error = on_error
        self._seg = Segment(self.path, self.custom_data, compression)
        #: every bag written, in order (the first is ``path``; more after a fallback)
        self.paths: list[Path] = [self.path]
        self.topics: dict[str, str] = {}
        self.received = self.written = self.dropped = self.chunks_flushed = 0
        self.lost = 0  # received but on no disk: after a failure with no fallback left
        self.error: BaseException | None = None
        self.error_message = ''
        self.failed = False  # recording stopped by a write failure
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=f'bag-writer:{self.path.name}',
                                        daemon=True)
        self._thread.start()

    # --- producer side (any thread) -------------------------------------------------------------
    def add_topic(self, topic: str, msgtype: str) -> None:
        """Register ``topic`` with ``msgtype`` ('pkg/msg/Name'); call before writing to it."""
        if topic in self.topics:
            if self.topics[topic] != msgtype:
                raise BagError(f'{self.path}: topic {topic} already recorded as {self.topics[topic]},'
                               f' not {msgtype}')
            return
        if msgtype not in typestore().types:
            raise BagError(f'{self.path}: cannot record {topic}: unknown message type {msgtype!r} '
                           '(expected a ROS 2 Jazzy standard type)')
        self.topics[topic] = msgtype
        self._q.put((_ADD, topic, msgtype))

    def set_custom_data(self, key: str, value: str) -> None:
        """Set ``key`` of the bag's custom data (metadata.yaml's ``custom_data``) to ``value``,
        in the file at once (an MCAP metadata record, which ``bag recover`` reads) and in the
        metadata.yaml written at close; a fallback bag starts with the latest values."""
        self.custom_data[key] = str(value)
        if not self._closed:
            self._q.put((_CUSTOM, {key: str(value)}))

    def write(self, topic: str, data: bytes, t_ns: int | None = None) -> bool:
        """Queue one serialized (CDR) message received at ``t_ns`` (default: now, system clock).
        Never blocks; False if closed, failed or the queue is full (dropped and counted)."""
        if self._closed:
            return False
        if self.failed:
            self.lost += 1
            return False
        if self._q.qsize() >= self.max_queue:
            self.dropped += 1
            return False
        self._q.put((topic, time.time_ns() if t_ns is None else t_ns, data))
        self.received += 1
        return True

    @property
    def pending(self) -> int:
        return self._q.qsize()

    @property
    def current_path(self) -> Path:
        """The bag being written now (``path``, or the fallback bag after a failure)."""
        return self.paths[-1]

    def close(self, timeout: float | None = 30.0) -> None:
        """Write everything queued, then the MCAP summary and metadata.yaml. Idempotent.

        Raises:
            BagError: the writer thread did not finish, or a write failure lost messages (the
                one-line message already given to ``on_error``).
        """
        if not self._closed:
            self._closed = True
            self._q.put(None)
        self._thread.join(timeout)
        if self._thread.is_alive():
            raise BagError(f'{self.path}: the writer thread did not finish within {timeout} s')
        if self.failed:
            raise BagError(self.error_message)

    def stats(self) -> dict:
        return {'received': self.received, 'written': self.written, 'dropped': self.dropped,
                'lost': self.lost, 'chunks_flushed': self.chunks_flushed, 'pending': self.pending,
                'bags': [str(p) for p in self.paths], 'failed': self.failed}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # --- the writer thread ----------------------------------------------------------------------
    def _run(self) -> None:
        seg: Segment | None = self._seg
        chunk_since = None  # monotonic time of the first message in the pending chunk
        tick = self.flush_period / 4
        get = self._q.get
        while True:
            try:
                item = get(timeout=tick)
            except queue.Empty:
                item = ()
            if item is None:
                break
            if seg is None:  # stopped by a failure: count what still arrives
                if item and item[0] is not _ADD and item[0] is not _CUSTOM:
                    self.lost += 1
                continue
            try:
                if item:
                    if item[0] is _ADD:
                        seg.add_connection(item[1], item[2])
                    elif item[0] is _CUSTOM:
                        seg.set_custom_data(item[1])
                        self.chunks_flushed += 1
                        chunk_since = None   # it closed the pending chunk
                    else:
                        seg.write(*item)
                        self.written += 1
                        if chunk_since is None:
                            chunk_since = time.monotonic()
                if chunk_since is not None and (
                        seg.pending_bytes >= self.chunk_size
                        or time.monotonic() - chunk_since >= self.flush_period):
                    seg.flush()
                    self.chunks_flushed += 1
                    chunk_since = None
            except Exception as exc:  # the disk: full, a size limit, an I/O error
                seg = self._failover(seg, exc)
                chunk_since = None if seg is None or not seg.unflushed else time.monotonic()
        if seg is not None:
            try:
                # the bag says what its recorder could not keep (queue full), for bag info and
                # for a recorder that ran in another process (haptic-anfis sim --record)
                seg.w.set_custom_data('dropped_messages', str(self.dropped))
                seg.close()
            except Exception as exc:  # the summary did not fit: seal what is there
                seg = self._failover(seg, exc)
                if seg is not None:
                    try:
                        seg.close()
                    except Exception as exc2:
                        self._failover(seg, exc2)

    def _failover(self, seg: Segment, exc: BaseException) -> Segment | None:
        """Seal ``seg`` after ``exc``; continue in a fallback bag if configured (its first
        messages: those of the failed chunk). Returns the segment to go on with, or None."""
        self.error = exc
        unflushed = list(seg.unflushed)
        kept = seg.good_messages
        how = seg.seal()
        what = (f'writing {seg.path} failed: {type(exc).__name__}: {exc}; it keeps the first '
                f'{kept} messages ({how})')
        nxt = None
        if self.fallback_dir is not None and seg.path.parent != self.fallback_dir:
            try:
                nxt = self._open_fallback(seg, unflushed)
            except Exception as exc2:
                what += f'; the fallback directory failed too: {exc2}'
        if nxt is not None:
            what += f'; recording continues in {nxt.path}'
            self.paths.append(nxt.path)
        else:
            self.failed = True
            self.lost += len(unflushed)
            self.written -= len(unflushed)
            what += (f'; recording STOPPED, {len(unflushed)} messages of the failed chunk lost'
                     + ('' if self.fallback_dir else ' (set a fallback directory to continue)'))
        self.error_message = what
        if self.on_error is not None:
            try:
                self.on_error(what)
            except Exception:
                pass
        return nxt

    def _open_fallback(self, seg: Segment, unflushed) -> Segment:
        name = seg.path.name
        dest = self.fallback_dir / name
        k = 2
        while dest.exists():
            dest = self.fallback_dir / f'{name}-{k}'
            k += 1
        custom = {**self.custom_data, 'continues': str(seg.path)}
        nxt = Segment(dest, custom, self.compression)
        for topic, msgtype in [(t, self.topics[t]) for t in seg.conns]:
            nxt.add_connection(topic, msgtype)
        for topic, t_ns, data in unflushed:
            nxt.write(topic, t_ns, data)
        nxt.flush()
        self.chunks_flushed += 1
        return nxt
