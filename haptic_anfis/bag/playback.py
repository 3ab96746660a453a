"""Playback timing (pure): when each recorded message is due, relative to the start of playback."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .errors import BagError
from .reader import read_messages


@dataclass(frozen=True)
class Recorded:
    t_ns: int       # receive time in the bag
    topic: str
    msgtype: str
    data: bytes     # serialized CDR


def load(path: str | Path, topics=None) -> list[Recorded]:
    """Every message of ``topics`` (None: all), in receive-time order, serialized."""
    return [Recorded(t, topic, ty, bytes(raw))
            for topic, ty, t, raw in read_messages(path, topics, deserialize=False)]


def due_times(records: list[Recorded], rate: float = 1.0, start_offset: float = 0.0):
    """``(seconds after playback start, record)`` for the records at or after ``start_offset``
    seconds into the bag, time scaled by 1/``rate`` (2.0 = twice as fast)."""
    if not rate > 0:
        raise BagError(f'rate {rate}: expected > 0')
    if not start_offset >= 0:
        raise BagError(f'start offset {start_offset}: expected >= 0 s')
    if not records:
        return []
    t0 = records[0].t_ns + int(round(start_offset * 1e9))
    return [((r.t_ns - t0) * 1e-9 / rate, r) for r in records if r.t_ns >= t0]
