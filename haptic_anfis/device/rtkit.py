"""Real-time priority without privilege: ask RealtimeKit (rtkit) over the system D-Bus (no ROS).

Why (issue 32): SCHED_FIFO needs CAP_SYS_NICE or an rtprio limit, which a trainee's account on a
lab PC has only if an administrator added one; without it the servo shares the cores with the
browser and everything else under the fair scheduler, and loses periods. Desktop Linux
distributions run ``rtkit-daemon`` (PipeWire and PulseAudio ask it for their audio threads). It
makes a thread of the caller's own process SCHED_RR, up to its ``MaxRealtimePriority`` (20 by
default), when polkit allows it (rtkit's default policy: a user with a local login session,
active or not; not a remote one) and once the process's ``RLIMIT_RTTIME`` is at most its
``RTTimeUSecMax`` (200 ms by default): a real-time thread that runs that long without blocking is
killed, so a runaway thread cannot freeze the desktop; rtkit also takes the priority back from
every thread it raised if its own canary thread starves.

Only the servo's threads ask (the compiled tick workers, the real Falcon's device loop, the
Python servo thread): each blocks every period. The graph's nodes do not: loading a case compiles
models for seconds without blocking, which that limit would kill.

The bus is spoken to with jeepney (pure Python, no C library, no event loop): one blocking
connection per request, closed at once.
"""
from __future__ import annotations

import os
import resource
import threading
from typing import Any, Callable

from ..errors import HapticAnfisError

__all__ = ['OBJECT_PATH', 'SERVICE', 'RealtimeKitError', 'limit_rttime', 'make_thread_realtime',
           'max_realtime_priority']

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
    if priority < 1:
        raise ValueError(f'priority: got {priority}, expected 1-99')
    with _Bus(connect, timeout) as bus:
        granted = max(1, min(int(priority), bus.prop('MaxRealtimePriority')))
        limit_rttime(bus.prop('RTTimeUSecMax'))
        tid = threading.get_native_id() if tid is None else int(tid)
        bus.call('MakeThreadRealtimeWithPID', 'ttu', (os.getpid(), tid, granted))
    return granted


def max_realtime_priority(*, connect: Callable[[], Any] | None = None,
                          timeout: float = 2.0) -> int:
    """rtkit's ``MaxRealtimePriority`` (whether it answers at all, for a report); raises
    :class:`RealtimeKitError`."""
    with _Bus(connect, timeout) as bus:
        return bus.prop('MaxRealtimePriority')


class _Bus:
    """One blocking connection to rtkit for one request; every failure a RealtimeKitError."""

    def __init__(self, connect: Callable[[], Any] | None, timeout: float) -> None:
        try:
            from jeepney import DBusAddress, new_method_call
            from jeepney.io.blocking import open_dbus_connection
            from jeepney.wrappers import DBusErrorResponse, unwrap_msg
        except ImportError:
            raise RealtimeKitError('rtkit: jeepney is not installed (pip install jeepney)') \
                from None
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
        if exc is None or isinstance(exc, RealtimeKitError):
            return
        if isinstance(exc, self._error):
            why = _MEANING.get(exc.name, exc.name)
            detail = f': {exc.data[0]}' if exc.data and isinstance(exc.data[0], str) else ''
            raise RealtimeKitError(f'rtkit: {why}{detail}') from None
        if isinstance(exc, (OSError, TimeoutError, ValueError, IndexError, TypeError)):
            raise RealtimeKitError(f'rtkit: {type(exc).__name__}: {exc}') from None

    def call(self, method: str, signature: str = '', body: tuple = (), address=None) -> tuple:
        msg = self._new(address or self.kit, method, signature, body)
        reply = self.conn.send_and_get_reply(msg, timeout=self.timeout)
        return tuple(self._unwrap(reply))  # an error reply raises DBusErrorResponse

    def prop(self, name: str) -> int:
        (value,) = self.call('Get', 'ss', (SERVICE, name), self.props)
        return int(value[1])  # a variant: (signature, value)


def limit_rttime(usec: int) -> None:
    """Lower this process's ``RLIMIT_RTTIME`` (soft and hard) to at most ``usec`` microseconds;
    a lower limit already set is kept."""
    soft, hard = resource.getrlimit(resource.RLIMIT_RTTIME)
    inf = resource.RLIM_INFINITY
    hard = usec if hard == inf else min(hard, usec)
    soft = hard if soft == inf else min(soft, hard)
    resource.setrlimit(resource.RLIMIT_RTTIME, (soft, hard))
