"""The servo process's loop for a device only Python can drive (the Falcon's USB library).

The real Falcon's USB library (pyftdi over pyusb) is Python, so its I/O cannot run inside the
compiled ``nogil`` loop of :mod:`.native_tick`. It runs instead in a servo process of its own
(forked by :class:`~.servo_native.NativeServoLoop` with ``device_factory``; its own session,
so its own scheduler autogroup), which holds nothing but the device and this loop: no ROS, no
executors, no recorder, no view. Each period it

1. reads the device (:meth:`~.falcon.Device.read`: the reply to the last command packet),
2. writes the reading into the tick's ``hand`` buffer and runs the compiled
   :func:`~.native_tick.tick` (``cfg[device]`` = 1: clutch, local-model rendering or ZOH,
   passivity bound, safety layer with its watchdog on the age of the node's last command),
3. writes the tick's force to the device.

The node (the driver, the ROS side) exchanges commands, models and published ticks with it
through the same shared-memory buffers as the simulated Falcon's servo process. A node that
freezes, even SIGSTOPped, cannot hold this process's interpreter lock: the watchdog in the
tick zeroes the force within ``watchdog_timeout`` of the node's last command, and the
device's own stall guard (a thread of THIS process, :meth:`~.falcon_usb.FalconUSB.check_stall`)
sends zero force when this loop itself sends nothing for ``stall_timeout``.

Everything the node needs to know about the device comes back as int64 counters
(:data:`DEV`) and one error message (:data:`MESSAGE_BYTES` bytes, UTF-8). Pure Python and
numpy, no ROS.
"""
from __future__ import annotations

import enum
import os
import time
from typing import Callable

import numpy as np

from . import native_tick as nt

__all__ = ['DEV', 'DEV_LEN', 'MESSAGE_BYTES', 'STARTING', 'RUNNING', 'FAILED', 'STOPPED',
           'ProcessDevice', 'run_device_loop', 'read_message', 'write_message']

#: device status and counters (int64, written by the servo process only)
DEV = enum.IntEnum('DEV', 'state connected lost replies missed_replies stall_events disconnects '
                   'reconnects io_errors kinematics_errors motor_scaled loop_errors', start=0)
DEV_LEN = len(DEV)
STARTING, RUNNING, FAILED, STOPPED = 0, 1, 2, 3
#: room for the one error message the process leaves when it cannot open the device
MESSAGE_BYTES = 1024
_COUNTERS = ('replies', 'missed_replies', 'stall_events', 'disconnects', 'reconnects',
             'io_errors', 'kinematics_errors', 'motor_scaled')


def _say(msg: str) -> None:
    """A line on the process's stderr (the node's log file under ``launch``); never raises."""
    try:
        os.write(2, f'[servo process {os.getpid()}] {msg}\n'.encode('utf-8', 'replace'))
    except OSError:
        pass


def write_message(buf: np.ndarray, msg: str) -> None:
    """Store ``msg`` (truncated, NUL-terminated) in the uint8 buffer ``buf``."""
    data = msg.encode('utf-8', 'replace')[:len(buf) - 1]
    buf[:len(data)] = np.frombuffer(data, dtype=np.uint8)
    buf[len(data)] = 0


def read_message(buf: np.ndarray) -> str:
    raw = bytes(buf)
    return raw.split(b'\0', 1)[0].decode('utf-8', 'replace')


def _counters(dev, status: np.ndarray) -> None:
    for name in _COUNTERS:
        status[DEV[name]] = int(getattr(dev, name, 0))
    status[DEV.connected] = int(bool(getattr(dev, 'connected', True)))
    status[DEV.lost] = int(bool(getattr(dev, 'disconnected', False)))


class ProcessDevice:
    """The node's view of the device in the servo process: its counters, read from shared
    memory (the names of :class:`~.falcon_usb.FalconUSB`'s)."""

    def __init__(self, status: np.ndarray) -> None:
        self._status = status

    def __getattr__(self, name: str) -> int:
        if name in _COUNTERS:
            return int(self._status[DEV[name]])
        raise AttributeError(name)

    @property
    def state(self) -> int:
        """:data:`STARTING`, :data:`RUNNING`, :data:`FAILED` or :data:`STOPPED`."""
        return int(self._status[DEV.state])

    @property
    def connected(self) -> bool:
        return bool(self._status[DEV.connected]) and not self.disconnected

    @property
    def disconnected(self) -> bool:
        return bool(self._status[DEV.lost])

    @property
    def loop_errors(self) -> int:
        return int(self._status[DEV.loop_errors])


def run_device_loop(factory: Callable[[], object], cfg: np.ndarray, st: np.ndarray,
                    cnt: np.ndarray, script: nt.Script, buf: nt.Buffers, scratch: np.ndarray,
                    status: np.ndarray, message: np.ndarray,
                    clock: Callable[[], float] = time.monotonic,
                    sleep: Callable[[float], None] = time.sleep) -> int:
    """The servo process's loop (see the module docstring) until ``buf.ctl[stop]``; returns the
    exit status (0, or 1 when the device could not be opened: ``message`` says why).

    ``factory()`` builds the device IN this process (a USB handle must not cross a fork); its
    ``log``, ``on_disconnect`` and ``on_reconnect`` hooks, when it has them, are pointed at this
    process's stderr and at ``status``. The device is left at zero force and closed."""
    status[DEV.state] = STARTING
    try:
        dev = factory()
        for hook in ('log', 'on_disconnect', 'on_reconnect'):
            if hasattr(dev, hook):
                setattr(dev, hook, _say)
        dev.open(clock())
    except BaseException as exc:  # one line for the node; nothing was sent but zero
        write_message(message, str(exc) or type(exc).__name__)
        status[DEV.state] = FAILED
        return 1
    period = float(cfg[nt.CFG.period])
    ctl, hand = buf.ctl, buf.hand
    status[DEV.state] = RUNNING
    cnt[nt.CNT.running] = 1
    deadline = clock()
    try:
        while ctl[nt.CTL.stop] == 0:
            now = clock()
            if now - deadline > period:  # late: count it, re-synchronise (tick counts the loss)
                cnt[nt.CNT.deadline_misses] += 1
                deadline = now
            try:
                s = dev.read(now)
                H = nt.HAND
                hand[H.t] = now
                hand[H.x0:H.x0 + 3] = s.position
                hand[H.v0:H.v0 + 3] = s.velocity
                hand[H.b0], hand[H.b1] = s.buttons[0], s.buttons[1]
            except Exception as exc:  # a reading we cannot use: zero force, no tick from it
                status[DEV.loop_errors] += 1
                _say(f'device read failed: {exc}')
                nt._fault(st, cnt)
                force = (0.0, 0.0, 0.0)
            else:
                nt.tick(now, cfg, st, cnt, script, buf, scratch, time.time_ns())
                force = (float(st[nt.S.f0]), float(st[nt.S.f1]), float(st[nt.S.f2]))
            try:
                dev.write(force)
            except Exception as exc:
                status[DEV.loop_errors] += 1
                _say(f'device write failed: {exc}')
            _counters(dev, status)
            deadline += period
            wait = deadline - clock()
            if wait > 0:
                sleep(wait)
    finally:
        st[nt.S.f0:nt.S.f0 + 3] = 0.0
        try:
            dev.write((0.0, 0.0, 0.0))
        finally:
            dev.close()
            _counters(dev, status)
            cnt[nt.CNT.running] = 0
            status[DEV.state] = STOPPED
    return 0
