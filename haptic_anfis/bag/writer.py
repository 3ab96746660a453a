"""A rosbag2 writer (MCAP storage, metadata version 9) fed from a queue by its own thread.

Producers (subscription callbacks, a 1 kHz loop) only append ``(topic, time, serialized bytes)`` to
an unbounded ``queue.SimpleQueue`` (a C call, never blocks); the writer thread does all file work.
Crash safety: the pending MCAP chunk is closed and flushed to the OS at least every
``flush_period`` seconds (and once it holds ``chunk_size`` bytes), so a ``kill -9`` loses at most
the last ``flush_period`` of messages plus what is still queued; the file left behind has no
summary and no ``metadata.yaml`` — :func:`haptic_anfis.bag.recover_bag` rebuilds both.

Relies on rosbags 0.11's MCAP storage internals (``storage.chunk``, ``storage.close_chunk()``,
``storage.bio``) for the time-based chunk flush; the version is pinned to <0.12 in setup.py.
"""
from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

from .errors import BagError
from .topics import typestore

_ADD = object()


class BagWriter:
    """Write a rosbag2 bag from any thread without blocking it.

    Args:
        path: bag directory to create (must not exist; parents are created).
        flush_period: close + flush the pending chunk at least this often [s].
        chunk_size: close the pending chunk once it holds this many bytes.
        max_queue: messages allowed to wait for the writer thread; beyond that :meth:`write`
            drops the message, counts it in ``dropped`` and returns False.
        custom_data: strings stored in metadata.yaml's ``custom_data``.
    """

    def __init__(self, path: str | Path, *, flush_period: float = 0.5, chunk_size: int = 256 * 1024,
                 max_queue: int = 200_000, custom_data: dict[str, str] | None = None):
        from rosbags.rosbag2 import StoragePlugin, Writer
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path}: exists already; a recording needs a new directory '
                           '(choose another path or remove it)')
        if not flush_period > 0 or chunk_size <= 0 or max_queue <= 0:
            raise BagError(f'{self.path}: flush_period, chunk_size and max_queue must be > 0')
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.flush_period, self.chunk_size, self.max_queue = flush_period, chunk_size, max_queue
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        for k, v in (custom_data or {}).items():
            self._writer.set_custom_data(k, str(v))
        try:
            self._writer.open()
        except Exception as exc:  # permissions, disk, ...
            raise BagError(f'{self.path}: cannot create the bag: {exc}') from exc
        self.topics: dict[str, str] = {}
        self.received = self.written = self.dropped = self.chunks_flushed = 0
        self.error: BaseException | None = None
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

    def write(self, topic: str, data: bytes, t_ns: int | None = None) -> bool:
        """Queue one serialized (CDR) message received at ``t_ns`` (default: now, system clock).
        Never blocks; False if closed or the queue is full (the message is dropped and counted)."""
        if self._closed:
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

    def close(self, timeout: float | None = 30.0) -> None:
        """Write everything queued, then the MCAP summary and metadata.yaml. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._q.put(None)
        self._thread.join(timeout)
        if self._thread.is_alive():
            raise BagError(f'{self.path}: the writer thread did not finish within {timeout} s')
        if self.error is not None:
            raise BagError(f'{self.path}: writing failed: {self.error}') from self.error

    def stats(self) -> dict:
        return {'received': self.received, 'written': self.written, 'dropped': self.dropped,
                'chunks_flushed': self.chunks_flushed, 'pending': self.pending}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # --- the writer thread ----------------------------------------------------------------------
    def _run(self) -> None:
        w = self._writer
        storage = w.storage
        conns = {}
        ts = typestore()
        chunk_since = None  # monotonic time of the first message in the pending chunk
        tick = self.flush_period / 4
        get = self._q.get
        try:
            while True:
                try:
                    item = get(timeout=tick)
                except queue.Empty:
                    item = ()
                if item is None:
                    break
                if item:
                    if item[0] is _ADD:
                        conns[item[1]] = w.add_connection(item[1], item[2], typestore=ts)
                    elif self.error is None:
                        w.write(conns[item[0]], item[1], item[2])
                        self.written += 1
                        if chunk_since is None:
                            chunk_since = time.monotonic()
                if chunk_since is not None and (
                        storage.chunk.bio.tell() >= self.chunk_size
                        or time.monotonic() - chunk_since >= self.flush_period):
                    if storage.chunk.msgs:
                        storage.close_chunk()
                    storage.bio.flush()
                    self.chunks_flushed += 1
                    chunk_since = None
        except BaseException as exc:  # keep draining so producers never block; close() reports it
            self.error = exc
            while get() is not None:
                pass
        finally:
            try:
                w.close()
            except Exception as exc:
                if self.error is None:
                    self.error = exc
