"""Rebuild a valid bag (metadata.yaml + a complete MCAP) from what a killed recording left on disk.

A writer killed with SIGKILL leaves an MCAP without summary or footer, possibly ending in half a
chunk, and no metadata.yaml. ``mcap.StreamReader`` reads it front to back: every closed chunk
(schemas, channels and messages live inside the chunks) is salvaged, the torn tail is dropped;
the custom data (the case recorded, ...) comes from the metadata records the writer put between
the chunks as it was set (:data:`.segment.CUSTOM_RECORD`).
The messages are written to a new bag of the same name; the original file is kept beside it as
``<name>.mcap.damaged``.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .errors import BagError
from .lock import being_recorded
from .reader import read_messages
from .segment import CUSTOM_RECORD


@dataclass
class RecoveryReport:
    path: Path
    source: Path
    counts: dict[str, int] = field(default_factory=dict)
    stopped: str = ''
    already_valid: bool = False

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    def format(self) -> str:
        if self.already_valid:
            return f'{self.path}: already a valid bag; nothing to recover'
        lines = [f'{self.path}: recovered {self.messages} messages from {self.source.name} '
                 f'(original kept as {self.source.name}.damaged)']
        for t, n in sorted(self.counts.items()):
            lines.append(f'  {t}: {n}')
        if self.stopped:
            lines.append(f'  stopped at the damaged tail: {self.stopped}')
        return '\n'.join(lines)


def _is_valid(p: Path) -> bool:
    try:
        for _ in read_messages(p, deserialize=False):
            pass
        return True
    except BagError:
        return False


def recover_bag(path: str | Path) -> RecoveryReport:
    """Recover the bag directory ``path`` in place (see the module docstring)."""
    p = Path(path).resolve()   # '.' has no name to build the temporary bag's from
    if p.is_file() and p.suffix == '.mcap':
        p = p.parent
    if not p.is_dir():
        raise BagError(f'{p}: no such bag directory (expected the directory a recording wrote, '
                       'holding its .mcap file)')
    sources = sorted(p.glob('*.mcap'))
    if not sources:
        raise BagError(f'{p}: nothing to recover: no .mcap file in the directory')
    if len(sources) > 1:
        raise BagError(f'{p}: expected one .mcap file, found {", ".join(s.name for s in sources)}')
    src = sources[0]
    if being_recorded(src):   # moving a live file aside would lose the rest of the session
        raise BagError(f'{p}: being recorded ({src.name} is open in a recorder): nothing to '
                       'recover; it is closed, with its metadata.yaml, when the recording stops')
    if (p / 'metadata.yaml').is_file() and _is_valid(p):
        return RecoveryReport(p, src, already_valid=True)


    tmp_root = p.parent / f'.{p.name}.recovering'
    if tmp_root.exists():
        shutil.rmtree(tmp_root)
    tmp_root.mkdir()
    report = RecoveryReport(p, src)
    ts = get_typestore(Stores.ROS2_JAZZY)
    schemas: dict[int, Schema] = {}
    conns = {}
    try:
        writer = Writer(tmp_root / p.name, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
    except Exception as exc:
        shutil.rmtree(tmp_root, ignore_errors=True)
        raise BagError(f'{p}: cannot write the recovered bag beside it: {exc}') from None
    try:
        with src.open('rb') as fh:
            try:
                for rec in StreamReader(fh, skip_magic=False).records:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec
                    elif isinstance(rec, Channel):
                        sch = schemas.get(rec.schema_id)
                        if sch is None:
                            continue
                        if sch.name not in ts.types:
                            try:
                                ts.register(get_types_from_msg(sch.data.decode(), sch.name))
                            except Exception as exc:
                                why = ' '.join(str(exc).split())   # parse errors span lines
                                raise BagError(f'{src}: topic {rec.topic}: unknown message type '
                                               f'{sch.name!r} with an unreadable definition: '
                                               f'{why} (expected a ROS 2 recording)') from None
                        if rec.id not in conns:
                            conns[rec.id] = writer.add_connection(rec.topic, sch.name, typestore=ts)
                    elif isinstance(rec, Message):
                        c = conns.get(rec.channel_id)
                        if c is None:
                            continue
                        writer.write(c, rec.log_time, rec.data)
                        report.counts[c.topic] = report.counts.get(c.topic, 0) + 1
                    elif isinstance(rec, Metadata) and rec.name == CUSTOM_RECORD:
                        for k, v in rec.metadata.items():   # the latest value of each key
                            writer.set_custom_data(k, v)
            except BagError:
                raise
            except Exception as exc:  # the torn tail: EndOfFile, bad record, bad magic ...
                report.stopped = f'{type(exc).__name__}: {exc}' if str(exc) else type(exc).__name__
                if not conns and fh.tell() <= 8 + 64 and not report.counts:
                    magic_ok = src.read_bytes()[:8] == b'\x89MCAP0\r\n'
                    if not magic_ok:
                        raise BagError(f'{src}: not an MCAP file (bad magic); nothing to recover'
                                       ) from None
        writer.close()
    except BaseException:
        shutil.rmtree(tmp_root, ignore_errors=True)
        raise
    if not report.counts:
        shutil.rmtree(tmp_root, ignore_errors=True)
        raise BagError(f'{src}: no complete chunk to recover ({report.stopped or "empty"}); '
                       'a recording killed in its first flush period has nothing on disk yet')
    src.rename(src.with_name(src.name + '.damaged'))
    meta = p / 'metadata.yaml'
    if meta.exists():
        meta.rename(p / 'metadata.yaml.damaged')
    for f in (tmp_root / p.name).iterdir():
        shutil.move(str(f), str(p / f.name))
    shutil.rmtree(tmp_root, ignore_errors=True)
    return report
