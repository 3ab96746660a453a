"""One bag being written (rosbags ``Writer``, MCAP storage) with what a failing disk needs: the
file offset and per-topic counts of the last chunk known to be on disk, the messages written since
(to hand to a second bag), and :meth:`Segment.seal` to leave a readable bag after a write failed.

Relies on rosbags 0.11's MCAP storage internals (``storage.chunk``, ``storage.close_chunk()``,
``storage.bio``, ``storage.compressor``); the version is pinned to <0.12 in setup.py.
"""
from __future__ import annotations

import os
import struct
from io import BytesIO
from pathlib import Path

import lz4.frame
import zstandard
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import write_record, write_string, write_uint32

from .errors import BagError
from .lock import hold, release
from .topics import typestore

#: Chunk compressions the writer offers (MCAP chunk ``compression`` field; '' = none).
COMPRESSIONS = ('none', 'zstd', 'lz4')

#: Name of the MCAP metadata records holding the bag's custom data as it is set (metadata.yaml,
#: which also has it, is written only when the bag closes): ``bag recover`` restores it from them.
CUSTOM_RECORD = 'haptic_anfis.custom_data'

_MAGIC = b'\x89MCAP0\r\n'
# DataEnd (op 0x0F, crc 0 = not computed) then a Footer (op 0x02) with no summary section:
# a valid MCAP that readers index by scanning (rosbags: meta_scan; mcap: StreamReader).
_TAIL = (b'\x0f' + struct.pack('<QI', 4, 0) + b'\x02' + struct.pack('<QQQI', 20, 0, 0, 0)
         + _MAGIC)


def compressor(name: str):
    """``(mcap compression name, compress(bytes) -> bytes)`` for ``name`` in :data:`COMPRESSIONS`."""
    if name == 'none':
        return '', None
    if name == 'zstd':
        return 'zstd', zstandard.ZstdCompressor(level=1).compress
    if name == 'lz4':
        return 'lz4', lz4.frame.compress
    raise BagError(f'compression {name!r}: expected one of {", ".join(COMPRESSIONS)}')


def _count_metadata(mcap: Path, n: int) -> None:
    """Set the Statistics record's ``metadata_count`` of the closed ``mcap`` to ``n``: rosbags
    counts its own record (``rosbag2``) only, the file also holds the :data:`CUSTOM_RECORD`
    ones (not in the summary's metadata index: readers that want them scan the file). The
    summary has no CRC (rosbags writes 0), so the 4 bytes are patched in place."""
    with mcap.open('r+b') as fh:
        fh.seek(-8 - 29, os.SEEK_END)   # the footer record: op, length, 2 offsets, CRC
        op, _, _, summary_offset_start, _ = struct.unpack('<BQQQI', fh.read(29))
        if op != 0x02 or not summary_offset_start:
            return
        fh.seek(summary_offset_start)
        while True:   # Summary Offset records: op 0x0E, length, group opcode, start, length
            head = fh.read(26)
            if len(head) < 26 or head[0] != 0x0E:
                return
            group, start = head[9], struct.unpack('<Q', head[10:18])[0]
            if group == 0x0B:   # Statistics: op, length, messages u64, schemas u16,
                fh.seek(start + 1 + 8 + 8 + 2 + 4 + 4)   # channels u32, attachments u32
                fh.write(struct.pack('<I', n))
                return


class Segment:
    """A bag directory being written from one thread (the writer thread of :class:`BagWriter`)."""

    def __init__(self, path: Path, custom_data: dict[str, str], compression: str = 'none'):
        self.path = path
        if path.exists():
            raise BagError(f'{path}: exists already; a recording needs a new directory '
                           '(choose another path or remove it)')
        blocker = next((a for a in path.parents if a.exists() and not a.is_dir()), None)
        if blocker is not None:
            raise BagError(f'{path}: {blocker} is a file, not a folder (expected a path whose '
                           'parents are folders, or do not exist yet)')
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:  # no permission, a read-only disk, a path that vanished
            raise BagError(f'{path}: cannot create the folder it goes in: {exc.strerror} '
                           f'({exc.filename})') from exc
        self.w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        for k, v in custom_data.items():
            self.w.set_custom_data(k, str(v))
        name, fn = compressor(compression)
        self._custom_records = 0
        try:
            self.w.open()
            self.storage = self.w.storage
            if fn is not None:
                self.storage.compression, self.storage.compressor = name, fn
            if custom_data:   # in the file from its start: a crash keeps it for bag recover
                self._custom_record(custom_data)
            self.storage.bio.flush()
        except BagError:
            raise
        except Exception as exc:  # permissions, disk, ...
            storage = getattr(self.w, 'storage', None)
            if storage is not None:
                try:
                    storage.bio.close()
                except Exception:
                    pass
            raise BagError(f'{path}: cannot create the bag: {exc}') from exc
        self.mcap = Path(self.storage.path)
        self._lock = hold(self.mcap)   # bag info / recover: being recorded, not interrupted
        self.conns: dict[str, object] = {}
        # The last state known to be on disk (after a successful flush) ...
        self.good_offset = self.storage.bio.tell()
        self.good_counts: dict[int, int] = {}
        self.good_span = (2**63 - 1, 0)
        self.good_messages = 0
        # ... and what was written since: handed to the next bag if the disk fails.
        self.unflushed: list[tuple[str, int, bytes]] = []

    def add_connection(self, topic: str, msgtype: str) -> None:
        self.conns[topic] = self.w.add_connection(topic, msgtype, typestore=typestore())

    def write(self, topic: str, t_ns: int, data: bytes) -> None:
        # Kept first: rosbags closes a chunk by itself past its size limit, inside this write;
        # if that fails (a full disk) the message is in the lost chunk and goes to the next bag.
        self.unflushed.append((topic, t_ns, data))
        self.w.write(self.conns[topic], t_ns, data)

    def set_custom_data(self, data: dict[str, str]) -> None:
        """Set custom data entries (metadata.yaml at close, and a metadata record now)."""
        for k, v in data.items():
            self.w.set_custom_data(k, str(v))
        self._custom_record(data)
        self.flush()   # on disk with the chunk before it (a failure cuts back to this point)

    def _custom_record(self, data: dict[str, str]) -> None:
        """An MCAP Metadata record (op 0x0C) named :data:`CUSTOM_RECORD` with ``data``; written
        between chunks (the pending chunk is kept apart until it closes)."""
        rec, kv = BytesIO(), BytesIO()
        write_string(rec, CUSTOM_RECORD)
        for k, v in data.items():
            write_string(kv, str(k))
            write_string(kv, str(v))
        write_uint32(rec, kv.tell())
        rec.write(kv.getbuffer())
        write_record(self.storage.bio, 0x0C, rec)
        self._custom_records += 1

    @property
    def pending_bytes(self) -> int:
        return self.storage.chunk.bio.tell()

    def flush(self) -> None:
        """Close the pending chunk and hand it to the OS; then it counts as on disk."""
        if self.storage.chunk.msgs:
            self.storage.close_chunk()
        self.storage.bio.flush()
        self.good_offset = self.storage.bio.tell()
        self.good_counts = dict(self.w.counts)
        self.good_span = (self.w.min_timestamp, self.w.max_timestamp)
        self.good_messages = sum(self.good_counts.values())
        self.unflushed.clear()

    def close(self) -> None:
        """Write the last chunk, the summary and metadata.yaml (rosbags' normal close)."""
        self.flush()
        self.w.close()
        release(self._lock)
        if self._custom_records:
            _count_metadata(self.mcap, 1 + self._custom_records)

    def seal(self) -> str:
        """After a write failed: keep what is on disk as a readable bag; say what was done.

        The MCAP is cut back to the end of the last chunk flushed whole (dropping a torn chunk),
        closed with a footer that has no summary (readers scan it), and metadata.yaml is written
        with the counts of what the file holds. If the disk has no room even for that (~60 B and
        the metadata), the file is left cut back, without footer: ``bag recover`` rebuilds it.
        """
        try:
            self.storage.bio.close()  # flushes what it can, then closes the file in any case
        except Exception:
            pass
        release(self._lock)
        try:
            os.truncate(self.mcap, self.good_offset)
            with self.mcap.open('ab') as fh:
                fh.write(_TAIL)
        except OSError as exc:
            try:
                os.truncate(self.mcap, self.good_offset)
            except OSError:
                pass
            return f'cut back to its last whole chunk; no room to close it ({exc.strerror})'
        try:
            self._write_metadata()
        except Exception as exc:
            for f in (self.path / 'metadata.yaml.tmp', self.path / 'metadata.yaml'):
                f.unlink(missing_ok=True)
            return f'closed without metadata.yaml ({exc})'
        return 'closed'

    def _write_metadata(self) -> None:
        """rosbags' metadata.yaml for what is on disk (its close() with the storage left out)."""
        mcap = self.mcap

        class _Written:  # the storage's close() is replaced: the file is closed already
            path = mcap

            def close(self, version, metadata):
                pass

        w = self.w
        w.storage = _Written()
        w.counts = dict(self.good_counts)
        for c in w.connections:
            w.counts.setdefault(c.id, 0)
        w.min_timestamp, w.max_timestamp = self.good_span
        if not self.good_messages:
            w.min_timestamp = w.max_timestamp = 0
        w.close()
