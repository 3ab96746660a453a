"""Bag -> one CSV per topic with readable columns.

Columns: ``t_recv`` (receive time, s, as recorded) then the message's fields flattened with dotted
names (``pose.position.x``); a ``builtin_interfaces/Time`` is one column in seconds
(``header.stamp``); a ``sensor_msgs/JointState`` whose names stay the same (the contact message)
gets one column per name (``contact_x`` ... ``saturated``; ``velocity.NAME``/``effort.NAME`` when
present); other sequences are one column, values joined by ``;``.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .errors import BagError
from .reader import read_messages


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
    return row


def csv_name(topic: str) -> str:
    return topic.strip('/').replace('/', '__') + '.csv'


def export_csv(path: str | Path, out_dir: str | Path, topics=None) -> dict[str, tuple[Path, int]]:
    """Write one CSV per topic into ``out_dir``; {topic: (csv path, rows)}."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise BagError(f'{out}: exists and is not a directory (expected an output directory)')
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[str, list[dict]] = {}
    names: dict[str, list[str] | None] = {}
    for topic, msgtype, t, msg in read_messages(path, topics):
        row = None
        if msgtype == 'sensor_msgs/msg/JointState':
            if topic not in names:
                names[topic] = list(msg.name)
            if names[topic] is not None:
                row = _joint_state_row(msg, names[topic])
                if row is None:  # names changed: the generic layout from here on; the rows
                    names[topic] = None  # written so far keep theirs (the CSV takes both columns)
        if row is None:
            row = flatten(msg)
        rows.setdefault(topic, []).append({'t_recv': f'{t // 10**9}.{t % 10**9:09d}', **row})
    written = {}
    for topic, rs in rows.items():
        cols: list[str] = []
        for r in rs:
            for k in r:
                if k not in cols:
                    cols.append(k)
        f = out / csv_name(topic)
        with f.open('w', newline='') as fh:
            w = csv.DictWriter(fh, fieldnames=cols)
            w.writeheader()
            w.writerows(rs)
        written[topic] = (f, len(rs))
    return written
