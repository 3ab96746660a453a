"""The servo loop: its own thread, fixed period, absolute deadlines (no ROS).

Each tick: read the device, hand the reading to ``on_state`` (the driver publishes it), let
``render`` offer the safety layer this tick's force (the local force model, evaluated at this
tick's position), ask the safety layer for the force and write it to the device; optionally append
the tick to a :class:`~.trace.TickTrace`. Sleeping to absolute deadlines absorbs
``time.sleep`` overshoot; a tick that starts more than a period late counts as a deadline miss and
the schedule re-synchronises (no burst of catch-up ticks). On exit the safety layer is stopped and
the device gets zero force.
"""
from __future__ import annotations

import contextlib
import math
import threading
import time
from typing import Callable, Iterator

from .falcon import Device, DeviceState
from .safety import SafetyLayer
from .stats import LoopStats
from .trace import DISABLED, TickTrace


class ServoLoop:
    """Run ``device`` at ``rate`` Hz on a daemon thread through ``safety``.

    ``on_state(state, force, now)`` runs on the servo thread after each read; ``force`` is the
    force applied in the previous tick (device frame). Exceptions in it are counted and the loop
    keeps running (``errors``; the last one in ``last_error``). ``render(state, now) -> int``
    runs next (same error handling) and returns the tick's status code, kept in ``status`` and
    written to ``trace`` (a :class:`~.trace.TickTrace`, or None) with the applied force.
    """

    def __init__(self, device: Device, safety: SafetyLayer, rate: float = 1000.0,
                 on_state: Callable[[DeviceState, tuple, float], None] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 render: Callable[[DeviceState, float], int] | None = None,
                 trace: TickTrace | None = None, priority: int = 0):
        if not rate > 0:
            raise ValueError(f'rate: expected > 0 Hz, got {rate!r}')
        if not 0 <= priority <= 99:
            raise ValueError(f'priority: expected 0 (normal scheduling) to 99, got {priority!r}')
        self.priority = int(priority)
        #: how the servo thread is scheduled (set by the thread as it starts; see set_realtime)
        self.scheduling = ''
        self._scheduled = threading.Event()
        self.device, self.safety, self.on_state, self.clock = device, safety, on_state, clock
        self.render, self.trace, self.status = render, trace, -1
        self.period = 1.0 / rate
        self.stats = LoopStats(period=self.period,
                               watchdog=getattr(safety, 'watchdog_timeout', math.inf))
        self.errors = 0
        self.last_error: BaseException | None = None
        self.force = (0.0, 0.0, 0.0)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        now = self.clock()
        self.device.open(now)
        self.safety.start(now)
        self._thread = threading.Thread(target=self._run, name='servo', daemon=True)
        self._thread.start()
        self._scheduled.wait(1.0)  # so that the caller can log how the thread runs

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        self.safety.stop()
        self.device.write((0.0, 0.0, 0.0))
        self.device.close()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def tick(self, now: float) -> None:
        """One servo cycle at time ``now`` (also usable without the thread, e.g. in tests)."""
        state = self.device.read(now)
        if self.on_state is not None:
            try:
                self.on_state(state, self.force, now)
            except Exception as exc:  # a publishing hiccup must not stop the servo
                self.errors += 1
                self.last_error = exc
        if self.render is not None:
            try:
                self.status = self.render(state, now)
            except Exception as exc:  # as above: the safety layer's watchdog covers a failure
                self.errors += 1
                self.last_error = exc
        f = self.safety.output(now)
        self.device.write(f)
        self.force = f
        if self.trace is not None:
            self.trace.add(now, state.position, f,
                           self.status if self.safety.enabled else DISABLED)
        n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) ** 0.5
        if n > self.stats.max_force:
            self.stats.max_force = n
        self.stats.tick(now)

    def _run(self) -> None:
        name_thread('servo-tick')
        self.scheduling = schedule_servo_thread(self.priority)
        self._scheduled.set()
        period, clock, stop = self.period, self.clock, self._stop
        deadline = clock()
        while not stop.is_set():
            now = clock()
            if now - deadline > period:
                self.stats.deadline_misses += 1
                deadline = now  # re-synchronise
            try:
                self.tick(now)
            except Exception as exc:  # a device read/write failure: zero force, keep the period
                self.errors += 1
                self.last_error = exc
                self.safety.stop()
                self.safety.start(now)  # starts at zero; the watchdog needs a new command
                try:
                    self.device.write((0.0, 0.0, 0.0))
                except Exception:
                    pass
            deadline += period
            delay = deadline - clock()
            if delay > 0:
                time.sleep(delay)
        self.safety.stop()
        self.device.write((0.0, 0.0, 0.0))


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
    import os
    try:
        policy = os.SCHED_FIFO if policy is None else policy
        os.sched_setscheduler(0, policy, os.sched_param(int(priority)))
    except (OSError, AttributeError) as exc:  # EPERM without the right; not Linux
        if not rtkit:
            return realtime_refused(priority, exc)
        from .rtkit import RealtimeKitError, make_thread_realtime
        try:
            got = make_thread_realtime(priority)
        except RealtimeKitError as kit:
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
    import os
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
    import os
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
    import os
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
    import ctypes
    import sys
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
    import ctypes
    import struct
    import sys
    if not sys.platform.startswith('linux'):
        return ''
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        # struct sched_attr: size, policy, flags, nice, priority, runtime, deadline, period,
        # util_min, util_max
        attr = ctypes.create_string_buffer(struct.pack('IIQiIQQQII', 56, 0, 0, 0, 0,
                                                       int(slice_s * 1e9), 0, 0, 0, 0), 56)
        nr = {'x86_64': 314, 'aarch64': 274}.get(__import__('platform').machine())
        if nr is None or libc.syscall(nr, 0, attr, 0) != 0:
            return ''
    except (OSError, AttributeError):
        return ''
    return f', time slice {slice_s * 1e3:g} ms requested'
