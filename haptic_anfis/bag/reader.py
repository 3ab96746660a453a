"""Open, check and read rosbag2 bags (any storage rosbags reads; this package writes MCAP)."""
from __future__ import annotations

import datetime as _dt
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import yaml
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from .errors import BagError
from .lock import being_recorded

_EXPECTED = 'expected a rosbag2 bag: a directory with metadata.yaml and its .mcap (or .db3) file'


def _recover_hint(path: Path) -> str:
    return f'run "haptic-anfis bag recover {path}" to rebuild it from what is on disk'


def check_bag_path(path: str | Path) -> Path:
    """``path`` as a Path if it looks like a bag; BagError saying what is wrong otherwise."""
    p = Path(path)
    if not p.exists():
        raise BagError(f'{p}: no such file or directory ({_EXPECTED})')
    if p.is_file():
        if p.suffix in ('.mcap', '.db3'):
            return p
        raise BagError(f'{p}: not a bag ({_EXPECTED})')
    if not (p / 'metadata.yaml').is_file():
        live = [m.name for m in p.glob('*.mcap') if being_recorded(m)]
        if live:
            raise BagError(f'{p}: being recorded ({", ".join(live)} is open in a recorder); '
                           'metadata.yaml is written when the recording stops')
        if any(p.glob('*.mcap')):
            raise BagError(f'{p}: metadata.yaml is missing (an interrupted recording?); '
                           + _recover_hint(p))
        raise BagError(f'{p}: not a bag: no metadata.yaml ({_EXPECTED})')
    return p


@contextmanager
def open_bag(path: str | Path):
    """A rosbags ``Reader`` opened on the bag at ``path``; every failure is a BagError naming it."""
    p = check_bag_path(path)
    try:
        reader = Reader(p)
        reader.open()
    except BagError:
        raise
    except Exception as exc:  # ReaderError, yaml errors, truncated files, ...
        hint = _recover_hint(p) if p.is_dir() else 'is the file complete?'
        why = ' '.join(str(exc).split())  # one line: yaml errors quote the file over several
        raise BagError(f'{p}: cannot open the bag: {why}; {hint}') from None
    try:
        yield reader
    finally:
        try:
            reader.close()
        except Exception:
            pass


def bag_typestore(reader, path: Path):
    """A Jazzy typestore that also knows any non-standard type the bag carries a definition of."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    for c in reader.connections:
        if c.msgtype in ts.types:
            continue
        data = c.msgdef.data if c.msgdef else ''
        try:
            if not data:
                raise ValueError('the bag carries no definition of it')
            if c.msgdef.format == MessageDefinitionFormat.IDL:
                ts.register(get_types_from_idl(data))
            else:
                ts.register(get_types_from_msg(data, c.msgtype))
        except Exception as exc:
            raise BagError(f'{path}: topic {c.topic}: unknown message type {c.msgtype!r} '
                           f'(not a ROS 2 Jazzy type, and {exc})') from None
    return ts


def read_messages(path: str | Path, topics=None, *, deserialize: bool = True,
                  expect_types: dict[str, str] | None = None,
                  start_ns: int | None = None) -> Iterator[tuple]:
    """Yield ``(topic, msgtype, t_ns, msg)`` in receive-time order, streaming: one MCAP chunk at a
    time is in memory (plus the chunk index), whatever the bag's length.

    ``msg`` is a rosbags message object (``deserialize``) or the raw CDR bytes. ``topics`` limits
    the topics read (each must be in the bag). ``expect_types``: {topic: type} checked first.
    ``start_ns``: only messages received at or after this time (chunks before it are not read).
    """
    with open_bag(path) as reader:
        p = Path(path)
        by_topic = {c.topic: c for c in reader.connections}
        if topics:
            missing = [t for t in topics if t not in by_topic]
            if missing:
                raise BagError(f'{p}: no topic(s) {", ".join(missing)} in the bag '
                               f'(it has {", ".join(sorted(by_topic)) or "none"})')
        for topic, want in (expect_types or {}).items():
            if topic in by_topic and by_topic[topic].msgtype != want:
                raise BagError(f'{p}: topic {topic} has type {by_topic[topic].msgtype}, '
                               f'expected {want}')
        conns = [c for c in reader.connections if not topics or c.topic in topics]
        ts = bag_typestore(reader, p) if deserialize else None
        try:
            for c, t, raw in reader.messages(connections=conns, start=start_ns):
                if deserialize:
                    yield c.topic, c.msgtype, t, ts.deserialize_cdr(raw, c.msgtype)
                else:
                    yield c.topic, c.msgtype, t, raw
        except BagError:
            raise
        except Exception as exc:
            raise BagError(f'{p}: reading failed ({type(exc).__name__}: {exc}); the bag may be '
                           'truncated or damaged: ' + _recover_hint(p)) from None


@dataclass(frozen=True)
class TopicStats:
    topic: str
    msgtype: str
    count: int
    rate_hz: float


#: the custom data ``recorder`` of the package's recorder node: the bag's ``case`` and ``scene``
#: entries are its (``exam report`` reads them)
RECORDER_MARK = 'haptic_anfis recorder'


@dataclass(frozen=True)
class BagInfo:
    path: Path
    files: list[str]
    size_bytes: int
    storage: str
    start_ns: int
    end_ns: int
    message_count: int
    topics: list[TopicStats]
    custom_data: dict
    #: other files in the bag directory, counted in ``size_bytes`` (e.g. the ``*.damaged``
    #: originals ``bag recover`` keeps): [(name, bytes)]
    kept: list = ()

    @property
    def duration_s(self) -> float:
        return max(self.end_ns - self.start_ns, 0) * 1e-9


def bag_info(path: str | Path) -> BagInfo:
    """What ``ros2 bag info`` shows: files, size, duration, start/end, per-topic type/count/rate."""
    with open_bag(path) as reader:
        p = Path(path)
        meta = _metadata_yaml(p)
        files = [str(f) for f in meta.get('relative_file_paths', [])] or [p.name]
        size = (sum(f.stat().st_size for f in p.iterdir() if f.is_file()) if p.is_dir()
                else p.stat().st_size)
        kept = ([(f.name, f.stat().st_size) for f in sorted(p.iterdir())
                 if f.is_file() and f.name not in files and f.name != 'metadata.yaml']
                if p.is_dir() else [])
        n = reader.message_count
        # rosbags' end_time is just after the last message (an exclusive end): the last's own
        start, end = (reader.start_time, reader.end_time - 1) if n else (0, 0)
        dur = max(end - start, 0) * 1e-9
        counts: dict[tuple[str, str], int] = {}
        for c in reader.connections:
            counts[(c.topic, c.msgtype)] = counts.get((c.topic, c.msgtype), 0) + c.msgcount
        topics = [TopicStats(t, ty, k, (k - 1) / dur if dur > 0 and k > 1 else 0.0)
                  for (t, ty), k in sorted(counts.items())]
        if not p.is_dir():   # an MCAP file of a bag: its folder's metadata says its custom data
            up = _metadata_yaml(p.parent)
            custom = up.get('custom_data') if any(
                Path(str(f)).name == p.name for f in up.get('relative_file_paths') or []) else None
        else:
            custom = meta.get('custom_data')
        return BagInfo(p, files, size, meta.get('storage_identifier', p.suffix.lstrip('.')),
                       start, end, n, topics, {k: str(v) for k, v in (custom or {}).items()},
                       kept)


def recorded_summary(path: str | Path) -> dict:
    """What a recorder (maybe in another process) wrote to the closed bag ``path``, in the shape of
    the recorder's own summary: ``output``, ``topics``, ``written``, ``dropped`` (None if the
    bag does not say; ``error`` when it cannot be opened)."""
    try:
        info = bag_info(path)
    except Exception as exc:  # noqa: BLE001 (the recorder said why when it happened)
        return {'output': str(path), 'topics': [], 'written': 0, 'dropped': None,
                'error': str(exc)}
    dropped = info.custom_data.get('dropped_messages', '')
    return {'output': str(path), 'topics': [t.topic for t in info.topics],
            'written': info.message_count,
            'dropped': int(dropped) if dropped.isdigit() else None}


def _metadata_yaml(p: Path) -> dict:
    if not p.is_dir():
        return {}
    try:
        text = (p / 'metadata.yaml').read_text()
        info = (yaml.safe_load(text) or {}).get('rosbag2_bagfile_information', {}) or {}
        if info.get('custom_data'):
            # strings, as rosbag2 reads them: rosbags writes them unquoted, and YAML 1.1 would
            # read a case named 'no' or 'on' back as a boolean
            raw = (yaml.load(text, Loader=yaml.BaseLoader) or {}).get(
                'rosbag2_bagfile_information', {}) or {}
            info['custom_data'] = raw.get('custom_data') or {}
        return info
    except Exception:
        return {}


def _stamp(ns: int) -> str:
    t = _dt.datetime.fromtimestamp(ns * 1e-9, tz=_dt.timezone.utc)
    return f'{t:%Y-%m-%d %H:%M:%S.%f} UTC ({ns // 10**9}.{ns % 10**9:09d})'


def _size(n: int) -> str:
    v, u = next(((n / 1024 ** i, u) for i, u in ((3, 'GiB'), (2, 'MiB'), (1, 'KiB'))
                 if n >= 1024 ** i), (n, 'B'))
    return f'{v:.1f} {u}'


def format_info(info: BagInfo) -> str:
    kept = sum(n for _, n in info.kept)
    lines = [f'Bag:           {info.path}',
             f'Files:         {", ".join(info.files)}']
    if info.kept:
        lines.append('Kept files:    ' + ', '.join(f'{f} ({_size(n)})' for f, n in info.kept)
                     + ' (not part of the bag; counted in its size)')
    lines += [f'Bag size:      {_size(info.size_bytes)}'
              + (f' ({_size(kept)} of it in kept files)' if kept else ''),
             f'Storage id:    {info.storage}',
             f'Duration:      {info.duration_s:.3f} s',
             f'Start:         {_stamp(info.start_ns) if info.message_count else "-"}',
             f'End:           {_stamp(info.end_ns) if info.message_count else "-"}',
             f'Messages:      {info.message_count}']
    w = max([len(t.topic) for t in info.topics] + [5])
    wt = max([len(t.msgtype) for t in info.topics] + [4])
    lines.append(f'Topics:        {len(info.topics)}')
    lines.append(f'  {"topic":<{w}}  {"type":<{wt}}  {"count":>8}  {"rate Hz":>9}')
    for t in info.topics:
        lines.append(f'  {t.topic:<{w}}  {t.msgtype:<{wt}}  {t.count:>8}  {t.rate_hz:>9.1f}')
    for k, v in sorted(info.custom_data.items()):
        lines.append(f'custom_data:   {k} = {v}')
    return '\n'.join(lines)
