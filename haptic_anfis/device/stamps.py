"""A command's age is its stamp's age (no ROS): the driver's book of its own recent pose stamps.

Every force command (and local force model) carries the stamp of the driver's pose it answers.
The driver records, for each pose it publishes, the stamp (integer ns of the ROS/wall clock) and
its own monotonic time; a command is then judged by the pose it answers, not by when it arrived:

- a stamp later than the newest recorded one: from the future — rejected;
- a stamp not among the recent ones (older than the book, or never published): unknown — rejected;
- a known stamp whose pose is older than ``max_age``: stale — rejected.

A rejected command is not a fault: it is simply not taken, so the watchdog ramps the force down as
for a missing command. This is what stops a driver paused (SIGSTOP) with old commands queued from
rendering a force from a node that died long ago.

``record`` runs on the servo thread and ``check`` on the executor thread: a dict holds
stamp -> time and a ring of stamps evicts the oldest; single dict operations are atomic under
the GIL.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

OK, STALE, FUTURE, UNKNOWN = 'ok', 'stale', 'from the future', 'not a recent pose stamp'


@dataclass
class StampStats:
    """Rejections since construction (counted per reason)."""
    rejected_stale: int = 0
    rejected_future: int = 0
    rejected_unknown: int = 0

    @property
    def rejected(self) -> int:
        return self.rejected_stale + self.rejected_future + self.rejected_unknown


class StampBook:
    """The last ``size`` pose stamps [ns] with their monotonic times [s].

    Args:
        size: stamps remembered (at 1 kHz, 500 = the last 0.5 s: far beyond any watchdog).
    """

    def __init__(self, size: int = 500) -> None:
        if not (isinstance(size, int) and size >= 1):
            raise ValueError(f'size: expected an integer >= 1, got {size!r}')
        self.size = size
        self._times: dict[int, float] = {}
        self._ring: list[int | None] = [None] * size
        self._i = 0
        self.newest = -1  # newest stamp recorded [ns]
        self.stats = StampStats()

    def record(self, stamp_ns: int, now: float) -> None:
        """The driver published a pose stamped ``stamp_ns`` at its monotonic time ``now``."""
        old = self._ring[self._i]
        if old is not None:
            self._times.pop(old, None)
        self._ring[self._i] = stamp_ns
        self._i = (self._i + 1) % self.size
        self._times[stamp_ns] = now
        if stamp_ns > self.newest:
            self.newest = stamp_ns

    def check(self, stamp_ns: int, now: float, max_age: float) -> tuple[str, float]:
        """(OK or the reason, the pose's monotonic time or NaN) for a command stamped
        ``stamp_ns`` received at ``now``; a rejection is counted."""
        t = self._times.get(stamp_ns)
        if t is None:
            if stamp_ns > self.newest:
                self.stats.rejected_future += 1
                return FUTURE, math.nan
            self.stats.rejected_unknown += 1
            return UNKNOWN, math.nan
        if now - t > max_age:
            self.stats.rejected_stale += 1
            return STALE, t
        return OK, t
