"""Real-time priority without privilege: ask RealtimeKit (rtkit) over the system D-Bus (no ROS).

Why: SCHED_FIFO needs CAP_SYS_NICE or an rtprio limit, which a trainee's account on a
lab PC has only if an administrator added one; without it the servo shares the cores with the
browser and everything else under the fair scheduler, and loses periods. Desktop Linux
distributions run ``rtkit-daemon`` (PipeWire and PulseAudio ask it for their audio threads). It
makes a thread of the caller's own process SCHED_RR, up to its ``MaxRealtimePriority`` (20 by
default), when polkit allows it (rtkit's default policy: a user with a local login session,
active or not; not a remote one) and once the process's ``RLIMIT_RTTIME`` is at most its
``RTTimeUSecMax`` (200 ms by default): a real-time thread that runs that long without blocking is
killed, so a runaway thread cannot freeze the desktop; rtkit also takes the priority back from
every thread it raised if its own canary thread starves.

The servo's threads ask for themselves (the compiled tick workers, the real Falcon's device loop,
the Python servo thread): each blocks every period. The graph's nodes on the haptic path are
raised by whoever raises them (``realtime.processes.set_graph_priority``), a few threads each, with
a soft limit below rtkit's (:func:`make_threads_realtime`'s ``soft_share``): a node that computes
longer than that without blocking (a case switch, which steps off real-time priority for it)
gets SIGXCPU first and goes back to the normal scheduler, instead of being killed.

The bus is spoken to with jeepney (pure Python, no C library, no event loop): one blocking
connection per request, closed at once.
"""
from __future__ import annotations

import os
import resource
import threading
from typing import Any, Callable, Sequence

from jeepney import DBusAddress, new_method_call
from jeepney.io.blocking import open_dbus_connection
from jeepney.wrappers import DBusErrorResponse, unwrap_msg

from ..errors import HapticAnfisError

__all__ = ['OBJECT_PATH', 'SERVICE', 'RealtimeKitError', 'limit_rttime', 'make_thread_realtime',
           'make_threads_realtime', 'max_realtime_priority']

SERVICE = 'org.freedesktop.RealtimeKit1'
OBJECT_PATH = '/org/freedesktop/RealtimeKit1'

#: D-Bus error names and what they mean here, for the one-line reason.
_MEANING = {
    'org.freedesktop.DBus.Error.ServiceUnknown': 'no rtkit-daemon on this machine',
    'org.freedesktop.DBus.Error.NameHasNoOwner': 'no rtkit-daemon on this machine',
    'org.freedesktop.DBus.Error.AccessDenied': 'rtkit refused (polkit: no local login session?)',
    'org.freedesktop.DBus.Error.NoReply': 'rtkit did not answer',
}


class RealtimeKitError(HapticAnfisError, OSError):
    """rtkit could not be asked, or refused: the message says which, in one line."""


def make_thread_realtime(priority: int, tid: int | None = None, *,
                         connect: Callable[[], Any] | None = None, timeout: float = 2.0) -> int:
    """Ask rtkit to schedule thread ``tid`` of this process (default: the calling thread)
    SCHED_RR at ``priority``, lowered to rtkit's ``MaxRealtimePriority``; returns the priority
    granted. Lowers this process's ``RLIMIT_RTTIME`` to rtkit's ``RTTimeUSecMax`` first (never
    raises it), as rtkit requires. ``connect`` returns an open jeepney blocking connection
    (default: the system bus; tests pass their own). Raises :class:`RealtimeKitError`."""
    tid = threading.get_native_id() if tid is None else int(tid)
    granted, refused = make_threads_realtime(priority, [tid], connect=connect, timeout=timeout)
    if refused:
        raise RealtimeKitError(refused[tid])
    return granted


def make_threads_realtime(priority: int, tids: Sequence[int], pid: int | None = None, *,
                          soft_share: float | None = None, connect: Callable[[], Any] | None = None,
                          timeout: float = 2.0) -> tuple[int, dict[int, str]]:
    """Ask rtkit, over one connection, to schedule threads ``tids`` of process ``pid`` (None:
    this one; another process of the same user is allowed) SCHED_RR at ``priority``, lowered
    to rtkit's ``MaxRealtimePriority``. Lowers the process's ``RLIMIT_RTTIME`` first, as rtkit
    requires: the hard limit to rtkit's ``RTTimeUSecMax``, the soft limit to ``soft_share`` of
    it if given (SIGXCPU comes there, SIGKILL at the hard limit). Returns (the priority granted,
    {tid: rtkit's one-line refusal} for the threads not raised: one that ended, rtkit's limits
    of threads per user and requests per 20 s). Raises :class:`RealtimeKitError` when rtkit
    cannot be asked at all (no bus, no daemon) or its limit cannot be set."""
    if priority < 1:
        raise ValueError(f'priority: got {priority}, expected 1-99')
    pid = os.getpid() if pid is None else int(pid)
    refused: dict[int, str] = {}
    with _Bus(connect, timeout) as bus:
        granted = max(1, min(int(priority), bus.prop('MaxRealtimePriority')))
        usec = bus.prop('RTTimeUSecMax')
        limit_rttime(usec, pid=0 if pid == os.getpid() else pid,
                     soft_usec=None if soft_share is None else int(usec * soft_share))
        for tid in tids:
            try:
                bus.call('MakeThreadRealtimeWithPID', 'ttu', (pid, int(tid), granted))
            except Exception as exc:
                error = bus.as_error(exc)
                if error is None:
                    raise
                refused[int(tid)] = str(error)
    return granted, refused


def max_realtime_priority(*, connect: Callable[[], Any] | None = None,
                          timeout: float = 2.0) -> int:
    """rtkit's ``MaxRealtimePriority`` (whether it answers at all, for a report); raises
    :class:`RealtimeKitError`."""
    with _Bus(connect, timeout) as bus:
        return bus.prop('MaxRealtimePriority')


class _Bus:
    """One blocking connection to rtkit for one request; every failure a RealtimeKitError."""

    def __init__(self, connect: Callable[[], Any] | None, timeout: float) -> None:
        self._new, self._unwrap, self._error = new_method_call, unwrap_msg, DBusErrorResponse
        self.timeout = timeout
        self.kit = DBusAddress(OBJECT_PATH, bus_name=SERVICE, interface=SERVICE)
        self.props = DBusAddress(OBJECT_PATH, bus_name=SERVICE,
                                 interface='org.freedesktop.DBus.Properties')
        try:
            self.conn = (connect or (lambda: open_dbus_connection(bus='SYSTEM')))()
        except (OSError, KeyError, ValueError) as exc:  # no bus socket; a malformed address
            raise RealtimeKitError(f'rtkit: no system D-Bus ({exc})') from None

    def __enter__(self) -> '_Bus':
        return self

    def __exit__(self, kind, exc, tb) -> None:
        self.conn.close()
        error = None if exc is None or isinstance(exc, RealtimeKitError) else self.as_error(exc)
        if error is not None:
            raise error from None

    def as_error(self, exc: BaseException) -> RealtimeKitError | None:
        """``exc`` as the one-line :class:`RealtimeKitError` (None: not a failure of asking)."""
        if isinstance(exc, RealtimeKitError):
            return exc
        if isinstance(exc, self._error):
            why = _MEANING.get(exc.name, exc.name)
            detail = f': {exc.data[0]}' if exc.data and isinstance(exc.data[0], str) else ''
            return RealtimeKitError(f'rtkit: {why}{detail}')
        if isinstance(exc, (OSError, TimeoutError, ValueError, IndexError, TypeError)):
            return RealtimeKitError(f'rtkit: {type(exc).__name__}: {exc}')
        return None

    def call(self, method: str, signature: str = '', body: tuple = (), address=None) -> tuple:
        msg = self._new(address or self.kit, method, signature, body)
        reply = self.conn.send_and_get_reply(msg, timeout=self.timeout)
        return tuple(self._unwrap(reply))  # an error reply raises DBusErrorResponse

    def prop(self, name: str) -> int:
        (value,) = self.call('Get', 'ss', (SERVICE, name), self.props)
        return int(value[1])  # a variant: (signature, value)


def limit_rttime(usec: int, pid: int = 0, soft_usec: int | None = None) -> None:
    """Lower the ``RLIMIT_RTTIME`` of process ``pid`` (0: this one; another process of the same
    user is allowed) to at most ``usec`` microseconds, its soft limit also to at most
    ``soft_usec`` when given; a lower limit already set is kept."""
    soft, hard = (resource.getrlimit(resource.RLIMIT_RTTIME) if not pid
                  else resource.prlimit(pid, resource.RLIMIT_RTTIME))
    inf = resource.RLIM_INFINITY
    hard = usec if hard == inf else min(hard, usec)
    soft = hard if soft == inf else min(soft, hard)
    if soft_usec is not None:
        soft = min(soft, int(soft_usec))
    if not pid:
        resource.setrlimit(resource.RLIMIT_RTTIME, (soft, hard))
    else:
        resource.prlimit(pid, resource.RLIMIT_RTTIME, (soft, hard))
