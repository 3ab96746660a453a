"""Bag -> one CSV per topic with readable columns.

Columns: ``t_recv`` (receive time, s, as recorded) then the message's fields flattened with dotted
names (``pose.position.x``); a ``builtin_interfaces/Time`` is one column in seconds
(``header.stamp``); a ``sensor_msgs/JointState`` whose names stay the same (the contact message)
gets one column per name (``contact_x`` ... ``saturated``; ``velocity.NAME``/``effort.NAME`` when
present; the contact message's approach values in ``effort`` as ``effort.surface_x`` ...
``effort.normal_z``); other sequences are one column, values joined by ``;``.
"""
from __future__ import annotations

import csv
import json
import tempfile
from pathlib import Path

import numpy as np

from ..interfaces import APPROACH_FIELDS, CONTACT_FIELDS
from .errors import BagError
from .reader import bag_info, read_messages


def _secs(t) -> str:
    return f'{int(t.sec)}.{int(t.nanosec):09d}'


def flatten(msg, prefix: str = '') -> dict[str, object]:
    """{dotted field name: value} of a rosbags message (see the module docstring)."""
    out: dict[str, object] = {}
    name = type(msg).__msgtype__ if hasattr(type(msg), '__msgtype__') else ''
    if name == 'builtin_interfaces/msg/Time':
        out[prefix.rstrip('.')] = _secs(msg)
        return out
    for f in msg.__dataclass_fields__:
        if f == '__msgtype__':
            continue
        v = getattr(msg, f)
        key = prefix + f
        if hasattr(v, '__dataclass_fields__'):
            out.update(flatten(v, key + '.'))
        elif isinstance(v, (list, tuple, np.ndarray)):
            if len(v) and hasattr(v[0], '__dataclass_fields__'):
                out[key + '.len'] = len(v)
            else:
                out[key] = ';'.join(repr(float(x)) if isinstance(x, (float, np.floating)) else str(x)
                                    for x in v)
        else:
            out[key] = v
    return out


def _joint_state_row(msg, names: list[str]) -> dict[str, object] | None:
    if list(msg.name) != names:
        return None
    row: dict[str, object] = {'header.stamp': _secs(msg.header.stamp),
                              'header.frame_id': msg.header.frame_id}
    for field, pre in (('position', ''), ('velocity', 'velocity.'), ('effort', 'effort.')):
        vals = getattr(msg, field)
        if len(vals) == len(names):
            row.update({pre + n: repr(float(x)) for n, x in zip(names, vals)})
        elif (field == 'effort' and tuple(names) == CONTACT_FIELDS
              and len(vals) == len(APPROACH_FIELDS)):   # the contact message's approach values
            row.update({pre + n: repr(float(x)) for n, x in zip(APPROACH_FIELDS, vals)})
        elif len(vals):   # another length: one column, as other sequences
            row[field] = ';'.join(repr(float(x)) for x in vals)
    return row


def csv_name(topic: str) -> str:
    return topic.strip('/').replace('/', '__') + '.csv'


def _plain(v):
    return v.item() if hasattr(v, 'item') else str(v)


def export_csv(path: str | Path, out_dir: str | Path, topics=None
               ) -> dict[str, tuple[Path | None, int]]:
    """Write one CSV per topic into ``out_dir``; {topic: (csv path, rows)}, a topic without
    messages ``(None, 0)`` (no file). Streams: rows go to a temporary file per topic while the
    columns are gathered, then into the CSV; memory does not grow with the bag.

    Raises:
        BagError: the bag (or the topics asked for) holds no message at all, or a bad bag.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise BagError(f'{out}: exists and is not a directory (expected an output directory)')
    info = bag_info(path)
    wanted = list(topics) if topics else [t.topic for t in info.topics]
    out.mkdir(parents=True, exist_ok=True)
    spill: dict[str, dict] = {}
    names: dict[str, list[str] | None] = {}
    with tempfile.TemporaryDirectory(dir=out, prefix='.export-') as tmp:
        try:
            for topic, msgtype, t, msg in read_messages(path, topics):
                row = None
                if msgtype == 'sensor_msgs/msg/JointState':
                    if topic not in names:
                        names[topic] = list(msg.name)
                    if names[topic] is not None:
                        row = _joint_state_row(msg, names[topic])
                        if row is None:  # names changed: the generic layout from here on; the
                            names[topic] = None  # rows so far keep theirs (the CSV takes both)
                if row is None:
                    row = flatten(msg)
                row = {'t_recv': f'{t // 10**9}.{t % 10**9:09d}', **row}
                s = spill.get(topic)
                if s is None:
                    f = Path(tmp) / f'{len(spill)}.jsonl'
                    s = spill[topic] = {'path': f, 'fh': f.open('w'), 'cols': {}, 'n': 0}
                s['cols'].update(dict.fromkeys(row))   # insertion-ordered union of the columns
                s['fh'].write(json.dumps(row, default=_plain) + '\n')
                s['n'] += 1
        finally:
            for s in spill.values():
                s['fh'].close()
        if not spill:
            on = f' on {", ".join(wanted)}' if topics else ''
            raise BagError(f'{path}: no messages{on}; nothing to export')
        written: dict[str, tuple[Path | None, int]] = {t: (None, 0) for t in wanted}
        for topic, s in spill.items():
            f = out / csv_name(topic)
            with f.open('w', newline='') as fh, s['path'].open() as src:
                w = csv.DictWriter(fh, fieldnames=list(s['cols']))
                w.writeheader()
                for line in src:
                    w.writerow(json.loads(line))
            written[topic] = (f, s['n'])
    return written
