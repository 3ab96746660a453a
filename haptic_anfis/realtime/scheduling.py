"""How the servo threads are scheduled (no ROS): real-time priority (SCHED_FIFO, else SCHED_RR
from RealtimeKit, :mod:`.rtkit`), the fair scheduler's short time slice, thread names, stepping
off real-time for a long computation, and the cores the tick workers are pinned to."""
from __future__ import annotations

import contextlib
import ctypes
import os
import platform
import struct
import sys
from typing import Iterator

from . import rtkit as realtime_kit  # (``rtkit`` is a parameter name below)


def set_realtime(priority: int, rtkit: bool = False, policy: int | None = None) -> str:
    """Schedule the calling thread SCHED_FIFO at ``priority`` (1-99; 0 = leave it as it is);
    refused and ``rtkit``, ask RealtimeKit for SCHED_RR instead (:mod:`.rtkit`: no privilege
    needed on a desktop Linux with rtkit-daemon, at most its priority 20). ``policy``: another
    real-time policy to ask for first (as :func:`os.sched_getscheduler` gives it: a thread's
    own, back). Returns what was done, in words, for the log.

    Why: the servo thread sleeps to each 1 ms deadline; under the normal scheduler, when the
    machine's cores are busy (a visualizer or recorder process beside the loop, the loop's own
    executor thread), it waits for a core after waking and misses deadlines — measured on the
    2-core machine with the visualizer's dent in its own process: 966 Hz, ~300 misses in 20 s;
    SCHED_FIFO 50: 997-998 Hz, 21-32 misses (README, *Tissue deformation*). The thread sleeps
    every tick, so it cannot starve the machine (and Linux throttles real-time threads at 95 %
    of each second). Needs CAP_SYS_NICE or an rtprio limit (``ulimit -r``,
    /etc/security/limits.conf), or rtkit; without them the thread keeps the normal scheduler,
    and says so.
    """
    if priority <= 0:
        return 'normal scheduler (priority 0)'
    try:
        policy = os.SCHED_FIFO if policy is None else policy
        os.sched_setscheduler(0, policy, os.sched_param(int(priority)))
    except (OSError, AttributeError) as exc:  # EPERM without the right; not Linux
        if not rtkit:
            return realtime_refused(priority, exc)
        try:
            got = realtime_kit.make_thread_realtime(priority)
        except realtime_kit.RealtimeKitError as kit:
            return realtime_refused(priority, exc, kit)
        return f'SCHED_RR priority {got} from rtkit, in place of SCHED_FIFO {priority}'
    return f'{_RT_POLICIES.get(policy & ~RESET_ON_FORK, "SCHED_FIFO")} priority {priority}'


def realtime_refused(priority: int, exc: BaseException, kit: BaseException | None = None) -> str:
    """The log's words for a refused SCHED_FIFO ``priority``: why (and why rtkit did not grant
    it, ``kit``), and how to allow it."""
    why = getattr(exc, 'strerror', None) or str(exc)
    also = f'; {kit}' if kit is not None else ''
    return (f'normal scheduler: SCHED_FIFO {priority} refused ({why}{also}); allow it with '
            f'`ulimit -r {priority}` or an rtprio line in /etc/security/limits.conf')


def realtime_priority(pid: int = 0) -> int:
    """The real-time priority (SCHED_FIFO or SCHED_RR, whatever flag rtkit or-ed into the policy)
    of thread/process ``pid`` (0: the calling thread); 0 under a normal policy or when it
    cannot be read."""
    rt = _realtime_of(pid)
    return rt[1] if rt else 0


def realtime_policy(pid: int = 0) -> str:
    """'SCHED_FIFO priority N' or 'SCHED_RR priority N' for thread/process ``pid`` (0: the
    calling thread), '' under a normal policy or when it cannot be read."""
    rt = _realtime_of(pid)
    return f'{rt[0]} priority {rt[1]}' if rt else ''


def _realtime_of(pid: int) -> tuple[str, int] | None:
    try:
        name = _RT_POLICIES.get(os.sched_getscheduler(pid) & ~RESET_ON_FORK)
        return (name, os.sched_getparam(pid).sched_priority) if name else None
    except (OSError, AttributeError):
        return None


def is_realtime() -> bool:
    """Whether the calling thread runs under a real-time policy (SCHED_FIFO or SCHED_RR)."""
    return _realtime_of(0) is not None


#: Linux's SCHED_RESET_ON_FORK flag, or-ed into the policy (rtkit sets it).
RESET_ON_FORK = 0x40000000
#: Linux's real-time policies by number
_RT_POLICIES = {1: 'SCHED_FIFO', 2: 'SCHED_RR'}


def to_normal_scheduler(tid: int = 0) -> bool:
    """Thread ``tid`` (0: the calling thread) back to the normal scheduler; False where that
    was refused or the thread has ended. A thread rtkit raised carries SCHED_RESET_ON_FORK,
    which only a privileged thread may clear: it is kept."""
    try:
        flag = os.sched_getscheduler(tid) & RESET_ON_FORK
        os.sched_setscheduler(tid, os.SCHED_OTHER | flag, os.sched_param(0))
    except (OSError, AttributeError):
        return False
    return True


@contextlib.contextmanager
def off_realtime() -> Iterator[None]:
    """The calling thread under the normal scheduler for the block, then back to the real-time
    priority it had (SCHED_FIFO again where allowed, else SCHED_RR from rtkit; neither: it stays
    normal). Does nothing for a thread that is not real-time.

    Why: a case switch (a new mesh, a new model) computes for hundreds of milliseconds without
    blocking. At real-time priority that holds a core against everything under the normal
    scheduler (the view, the desktop), and rtkit's run-time limit (``RLIMIT_RTTIME``, 200 ms)
    would kill the node for it."""
    rt = _realtime_of(0)
    if rt is None:
        yield
        return
    policy, priority = os.sched_getscheduler(0), rt[1]
    to_normal_scheduler(0)
    try:
        yield
    finally:
        set_realtime(priority, rtkit=True, policy=policy)


def schedule_servo_thread(priority: int, rtkit: bool = True) -> str:
    """The calling servo thread's scheduling, best first: SCHED_FIFO ``priority``; refused,
    SCHED_RR from rtkit (``rtkit``); else the fair scheduler with a short time slice
    (:func:`request_short_slice`), also when the real-time priority was asked and refused.
    Returns what was done, in words, for the log."""
    words = set_realtime(priority, rtkit=rtkit)
    if not is_realtime():
        words += request_short_slice()
    return words


def name_thread(name: str) -> None:
    """Give the calling OS thread ``name`` (Linux keeps 15 bytes; the main thread's name is the
    process's): ``top -H``, ``ps -L`` and scheduler traces then say which thread is the servo's.
    Does nothing where the platform has no such name."""
    if not sys.platform.startswith('linux'):
        return
    try:
        ctypes.CDLL(None).prctl(15, name.encode()[:15], 0, 0, 0)  # PR_SET_NAME
    except (OSError, AttributeError):
        pass


def request_short_slice(slice_s: float = 0.0001) -> str:
    """Ask the kernel's fair scheduler (EEVDF, Linux >= 6.12) for a short time slice for the
    calling thread (``sched_setattr`` with SCHED_OTHER and ``sched_runtime``): a thread that
    sleeps most of each period then gets an earlier virtual deadline and preempts busy
    processes sooner when it wakes. Needs no privilege. Returns what was done, for the log
    ('' when the kernel refused: older kernels ignore or reject it).

    Measured (bench/bench_servo_load.py's prototype, 8 busy processes on 2 cores): a compiled
    1 kHz loop ran 946 Hz with it, 564 Hz without (SCHED_FIFO: 998 Hz).
    """
    if not sys.platform.startswith('linux'):
        return ''
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        # struct sched_attr: size, policy, flags, nice, priority, runtime, deadline, period,
        # util_min, util_max
        attr = ctypes.create_string_buffer(struct.pack('IIQiIQQQII', 56, 0, 0, 0, 0,
                                                       int(slice_s * 1e9), 0, 0, 0, 0), 56)
        nr = {'x86_64': 314, 'aarch64': 274}.get(platform.machine())
        if nr is None or libc.syscall(nr, 0, attr, 0) != 0:
            return ''
    except (OSError, AttributeError):
        return ''
    return f', time slice {slice_s * 1e3:g} ms requested'


def worker_cpus(n: int) -> list[int | None]:
    """The cores for ``n`` tick workers: distinct cores this process may run on, the first and
    the last of them first (on most machines different physical cores, whose interrupts and
    busy neighbours differ); fewer when fewer are allowed. ``[None]`` (one worker, unpinned)
    where affinity is not available."""
    try:
        allowed = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return [None]
    if n <= 1 or len(allowed) <= 1:
        return [None]
    order = [allowed[0], allowed[-1], *allowed[1:-1]]
    return order[:min(n, len(allowed))]
