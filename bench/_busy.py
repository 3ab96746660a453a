"""Processes that spin on the CPU beside a benchmark: the load of other programs.

    from _busy import busy   # bench/ is sys.path[0] when a bench script runs
    with busy(8):                 # 8 Python processes spinning until the block ends
        ...
    with busy(8, sessions=True):  # each in a session of its own, as a desktop's programs are
        ...

``sessions``: Linux's autogroup gives each session one fair share of the CPU, so 8 spinners in
8 sessions load a process in another session far more than 8 spinners sharing one session.
"""
from __future__ import annotations

import contextlib
import os
import signal
import statistics
import subprocess
import sys
import threading
from typing import Iterator

__all__ = ['busy', 'paused', 'LoadSampler']


@contextlib.contextmanager
def busy(n: int, sessions: bool = False) -> Iterator[list[subprocess.Popen]]:
    """``n`` processes spinning on the CPU for the block (``sessions``: each in a session of
    its own); ended, and waited for, when it leaves, also on an error."""
    procs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                              start_new_session=sessions) for _ in range(n)]
    try:
        yield procs
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait()


@contextlib.contextmanager
def paused(procs: list[subprocess.Popen]) -> Iterator[None]:
    """The processes of :func:`busy` stopped (SIGSTOP) for the block, continued after it: the
    benchmark's own analysis between runs (an hour's trace: minutes of CPU) is not what they
    load."""
    for p in procs:
        p.send_signal(signal.SIGSTOP)
    try:
        yield
    finally:
        for p in procs:
            p.send_signal(signal.SIGCONT)


def cpu_times() -> list[int] | None:
    """The machine's CPU time counters (``/proc/stat``'s ``cpu`` line, in clock ticks: user nice
    system idle iowait irq softirq steal ...), or None where there is no such file."""
    try:
        with open('/proc/stat') as f:
            return [int(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None


def steal_pct(before: list[int] | None, after: list[int] | None) -> float | None:
    """The share of CPU time [%] the hypervisor gave other guests between two
    :func:`cpu_times` readings ("steal", the 8th counter): a virtual machine's cores then run
    nobody's threads here, the servo thread's neither (None: no readings or no time passed)."""
    if not before or not after or len(before) < 8 or len(after) < 8:
        return None
    total = sum(after[:8]) - sum(before[:8])   # guest time is counted in user already
    return 100.0 * (after[7] - before[7]) / total if total > 0 else None


class LoadSampler:
    """The 1-minute load average read every ``every`` seconds while the block runs; ``median``
    afterwards. Read once at the start and once at the end (after the busy processes were
    stopped for the benchmark's own analysis) it said 3.9-4.7 of hours that stood at 14-17.
    ``steal``: the hypervisor's steal over the block [%] (:func:`steal_pct`): short rows of
    issue 32 that missed on a quiet machine ran under 0-27 % steal."""

    def __init__(self, every: float = 10.0) -> None:
        self.every, self.samples = every, []
        self.steal: float | None = None
        self._cpu0: list[int] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.every):
            self.samples.append(os.getloadavg()[0])

    def __enter__(self) -> LoadSampler:
        self._cpu0 = cpu_times()
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.steal = steal_pct(self._cpu0, cpu_times())

    @property
    def median(self) -> float | None:
        """The samples' median (None before the first: a block shorter than ``every``)."""
        return statistics.median(self.samples) if self.samples else None
