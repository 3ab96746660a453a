"""Playback (pure, streaming): the recorded messages in order with when each is due, relative to
the start of playback; memory stays bounded whatever the bag's length (one MCAP chunk at a time,
see :func:`haptic_anfis.bag.reader.read_messages`)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from .errors import BagError
from .reader import bag_info, read_messages


@dataclass(frozen=True)
class Recorded:
    t_ns: int       # receive time in the bag
    topic: str
    msgtype: str
    data: bytes     # serialized CDR


def check_timing(rate: float, start_offset: float) -> None:
    if not rate > 0:
        raise BagError(f'rate {rate}: expected > 0')
    if not start_offset >= 0:
        raise BagError(f'start offset {start_offset}: expected >= 0 s')


def stream(path: str | Path, topics=None, start_ns: int | None = None) -> Iterator[Recorded]:
    """Every message of ``topics`` (None: all) received at or after ``start_ns``, in receive-time
    order, serialized; read lazily."""
    for topic, ty, t, raw in read_messages(path, topics, deserialize=False, start_ns=start_ns):
        yield Recorded(t, topic, ty, bytes(raw))


def schedule(path: str | Path, topics=None, rate: float = 1.0, start_offset: float = 0.0,
             start_ns: int | None = None) -> Iterator[tuple[float, Recorded]]:
    """``(seconds after playback start, record)`` for the messages at or after ``start_offset``
    seconds into the bag, time scaled by 1/``rate`` (2.0 = twice as fast); lazily.
    ``start_ns``: the bag's first receive time, when the caller knows it (else read from the bag).
    """
    check_timing(rate, start_offset)
    if start_ns is None:
        start_ns = bag_info(path).start_ns
    t0 = start_ns + int(round(start_offset * 1e9))
    for r in stream(path, topics, t0):
        yield (r.t_ns - t0) * 1e-9 / rate, r

