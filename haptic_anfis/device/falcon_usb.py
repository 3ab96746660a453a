"""A real Novint Falcon behind the servo loop: USB transport (pyftdi) and the device backend.

:class:`FalconUSB` implements the same :class:`~haptic_anfis.device.falcon.Device` interface as
:class:`~haptic_anfis.device.falcon.SimulatedFalcon` (device frame, metres, newtons), so the
driver runs it around the same compiled servo tick, in a servo process of its own
(:mod:`.device_process`). Packets are in
:mod:`.falcon_protocol`, the delta-robot kinematics in :mod:`.falcon_kinematics`.

The USB library (``pyftdi``, pure Python over ``pyusb``/libusb) is optional: it is imported only
when a :class:`PyFtdiTransport` is made, and its absence gives a :class:`FalconUnavailableError`
telling the user to ``pip install 'haptic_anfis[falcon]'``. Tests use a fake in its place.

Device frame (what :meth:`FalconUSB.read` returns and :meth:`FalconUSB.write` takes): origin at
``center`` (a point near the middle of the Falcon's reach), x = the Falcon's z axis (towards the
user: pulling the grip back is +x, pushing it into the device is -x, the tissue frame's
"into the body"), y = the Falcon's x (user's right), z = the Falcon's y (up).

Hardware-side guard: every command packet the Falcon receives is applied until the next one
arrives, so a stalled host would leave the last force on. A guard thread watches the time since
the last packet sent; after ``stall_timeout`` it sends a zero-force packet itself (and logs it),
and the next servo packet ramps the force back up over ``resume_ramp`` seconds. The default
timeout comes from the servo thread's measured jitter (``bench/bench_falcon_jitter.py``; see
:data:`DEFAULT_STALL_TIMEOUT`). :meth:`FalconUSB.close` and an ``atexit`` hook send zero too. The
guard needs the Python interpreter to run: a frozen process cannot send anything, and whether the
Novint firmware has its own timeout is not known to us.

Losing the device: ``disconnect_after`` consecutive servo ticks without a reply (or with an I/O
error) mark the device disconnected: the velocity reads zero, no force is sent, ``on_disconnect``
is called (the driver logs it and zeroes its safety layer), and with ``reconnect`` the backend
tries to open it again every ``reconnect_period`` seconds (firmware reloaded and homing redone
as needed, force ramping back from zero); without it the driver stops with the message.

Force limits: ``max_force`` [N] bounds the tip force (default :data:`RATED_FORCE`); the three motor
command values are then scaled TOGETHER so that none exceeds ``max_motor_command`` counts
(clipping them one by one would bend the force's direction).

Nothing in this module has been tried on a real Falcon in this project.
"""
from __future__ import annotations

import atexit
import logging
import math
import threading
import time
from pathlib import Path
from typing import Callable

from . import falcon_protocol as fp
from .falcon import RATED_FORCE, Device, DeviceState
from .falcon_kinematics import (GEOMETRY, WORKSPACE_CENTER, FalconGeometry, KinematicsError,
                                force_to_torque, forward_kinematics, gravity_force,
                                inverse_kinematics, ticks_to_angles, torques_to_commands)
from ..errors import HapticAnfisError

INSTALL_HINT = "pip install 'haptic_anfis[falcon]'"
#: Default stall-guard timeout [s], chosen from the servo thread's measured write-to-write gaps
#: (bench/bench_falcon_jitter.py; figures in the README): on a 2-core machine at load 7-17 the
#: FalconUSB servo thread's p99.9 gap was 14 ms, gaps > 25 ms came about 4-6 times a minute and
#: > 50 ms about twice a minute at load 17 (none at load 7), where a 5 ms timeout tripped ~2000
#: times a minute. A real stall keeps the last force (<= max_force) on for at most this long.
DEFAULT_STALL_TIMEOUT = 0.05
#: Where the firmware file comes from (for error messages).
FIRMWARE_HINT = ("the Novint SDK ('nVent') firmware, nvent_firmware.bin — the file libnifalcon's "
                 "findfalcons loads, in the firmware/ folder of the libnifalcon sources "
                 "(github.com/libnifalcon/libnifalcon) and installed with Novint's Falcon drivers; "
                 "haptic_anfis ships none")
_log = logging.getLogger(__name__)


class FalconError(HapticAnfisError, OSError):
    """The Falcon could not be opened, loaded with firmware, homed or driven (message says why)."""


class FalconUnavailableError(FalconError):
    """The optional USB library is not installed."""


class FirmwareError(FalconError):
    """One firmware-upload attempt failed."""


# -- frames ----------------------------------------------------------------------------------------
def falcon_to_device(v):
    """A vector in the Falcon frame -> the device frame (x_dev = z_F, y_dev = x_F, z_dev = y_F)."""
    return (v[2], v[0], v[1])


def device_to_falcon(v):
    """Inverse of :func:`falcon_to_device`."""
    return (v[1], v[2], v[0])


# -- transport -------------------------------------------------------------------------------------
def import_ftdi():
    """``pyftdi.ftdi.Ftdi``, or :class:`FalconUnavailableError` with the install command."""
    try:
        from pyftdi.ftdi import Ftdi
    except ImportError as exc:
        raise FalconUnavailableError(
            f"backend 'falcon' needs the optional USB library pyftdi, which is not installed "
            f"({exc}): {INSTALL_HINT}") from None
    return Ftdi


class PyFtdiTransport:
    """The Falcon's FTDI chip through ``pyftdi`` (``ftdi_cls``: the ``Ftdi`` class; tests pass a
    fake with the same methods). Thin: every method is one pyftdi call."""

    def __init__(self, ftdi_cls=None):
        self.ftdi_cls = ftdi_cls if ftdi_cls is not None else import_ftdi()
        self.ftdi = None

    def list_devices(self) -> list[str]:
        """Serial numbers (or '?') of the Falcons on the bus."""
        try:
            found = self.ftdi_cls.find_all([(fp.VENDOR_ID, fp.PRODUCT_ID)], nocache=True)
        except Exception:  # listing is only for messages
            return []
        return [getattr(desc, 'sn', None) or '?' for desc, _ in found]

    def open(self, index: int = 0, serial: str = '') -> None:
        try:
            self.ftdi_cls.add_custom_product(fp.VENDOR_ID, fp.PRODUCT_ID, 'falcon')
        except ValueError:  # already registered
            pass
        ftdi = self.ftdi_cls()
        try:
            ftdi.open(fp.VENDOR_ID, fp.PRODUCT_ID, index=index, serial=serial or None)
        except Exception as exc:
            found = self.list_devices()
            which = f'serial {serial!r}' if serial else f'index {index}'
            raise FalconError(
                f'cannot open the Novint Falcon ({which}, USB {fp.VENDOR_ID:04x}:'
                f'{fp.PRODUCT_ID:04x}): {exc}. Falcons found: {len(found)}'
                + (f' (serials {", ".join(found)})' if found else '')
                + '. Check the USB cable and the power supply; on Linux the user needs access '
                f'to the device (a udev rule for {fp.VENDOR_ID:04x}:{fp.PRODUCT_ID:04x}).') from exc
        self.ftdi = ftdi

    def close(self) -> None:
        if self.ftdi is not None:
            try:
                self.ftdi.close()
            finally:
                self.ftdi = None

    def purge(self) -> None:
        self.ftdi.purge_buffers()

    def reset(self) -> None:
        self.ftdi.reset()

    def set_latency_ms(self, ms: int) -> None:
        self.ftdi.set_latency_timer(ms)

    def set_baudrate(self, baud: int) -> int:
        # The Falcon's rates (140000, 1456312) are not standard ones: take the nearest divisor.
        return self.ftdi.set_baudrate(baud, constrain=False)

    def set_line_8n1(self) -> None:
        self.ftdi.set_line_property(8, 1, 'N')
        self.ftdi.set_flowctrl('')

    def set_rts(self, state: bool) -> None:
        self.ftdi.set_rts(state)

    def set_dtr(self, state: bool) -> None:
        self.ftdi.set_dtr(state)

    def write(self, data: bytes) -> int:
        return self.ftdi.write_data(data)

    def read(self, max_bytes: int) -> bytes:
        """Whatever has arrived, at most ``max_bytes`` (may be empty)."""
        return bytes(self.ftdi.read_data_bytes(max_bytes, attempt=1))


# -- the backend -----------------------------------------------------------------------------------
class FalconUSB(Device):
    """A Novint Falcon over USB, device frame in and out (see the module docstring).

    Args:
        firmware_path: the Novint firmware file to upload when the device is not running one
            ('' = expect it already running, e.g. loaded by another tool since power-up).
        device_index, serial: which Falcon (serial wins when given).
        firmware_attempts: upload attempts before giving up (uploads often fail once or twice).
        homing: wait at connect (LED red, up to ``homing_timeout`` s) for the user to home the
            arms; with False a device that is not homed is an error (its encoders are relative
            to wherever the arms were at power-up).
        gravity_compensation, gravity_mass: add an upward force holding ``gravity_mass`` kg at the
            tip (the grip and arms lumped; an estimate to tune per device).
        max_force: limit on the total tip force [N] sent, gravity compensation included.
        max_motor_command: largest motor command magnitude [counts] (<= 32767); the three
            commands are scaled together under it.
        stall_timeout: the guard sends zero force when no packet went out for this long [s].
        resume_ramp: after a guard stop or a reconnect, the force limit ramps from 0 to
            ``max_force`` over this long [s].
        velocity_cutoff: first-order low-pass on the differentiated position [Hz].
        disconnect_after: this many consecutive ticks without a reply or with an I/O error mark
            the device disconnected.
        reconnect, reconnect_period: try to reopen a disconnected device every period [s].
        on_disconnect, on_reconnect: called (with a message) when the device is lost / back.
        transport: an object with :class:`PyFtdiTransport`'s methods (None: pyftdi).
        guard_thread: run the stall guard on its own thread (tests call :meth:`check_stall`).
        io_timeout: seconds to wait for a reply during firmware upload and probing.
        boot_query_tries: how often to send the bootloader query before an upload attempt fails.
    """

    def __init__(self, firmware_path: str = '', device_index: int = 0, serial: str = '',
                 firmware_attempts: int = 3, homing: bool = True, homing_timeout: float = 30.0,
                 gravity_compensation: bool = False, gravity_mass: float = 0.1,
                 max_force: float = RATED_FORCE, max_motor_command: int = fp.INT16_MAX,
                 stall_timeout: float = DEFAULT_STALL_TIMEOUT,
                 resume_ramp: float = 0.05, velocity_cutoff: float = 50.0,
                 disconnect_after: int = 200, reconnect: bool = True,
                 reconnect_period: float = 1.0,
                 on_disconnect: Callable[[str], None] | None = None,
                 on_reconnect: Callable[[str], None] | None = None,
                 geometry: FalconGeometry = GEOMETRY, center=WORKSPACE_CENTER,
                 transport=None, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 log: Callable[[str], None] | None = None, guard_thread: bool = True,
                 io_timeout: float = 0.5, boot_query_tries: int = fp.BOOT_QUERY_TRIES):
        for name, v, lo in (('firmware_attempts', firmware_attempts, 1),
                            ('disconnect_after', disconnect_after, 1),
                            ('boot_query_tries', boot_query_tries, 1)):
            if int(v) != v or int(v) < lo:
                raise ValueError(f'{name}: expected an integer >= {lo}, got {v!r}')
        if int(max_motor_command) != max_motor_command or not 1 <= max_motor_command <= fp.INT16_MAX:
            raise ValueError(f'max_motor_command: expected an integer in 1..{fp.INT16_MAX}, got '
                             f'{max_motor_command!r}')
        for name, v in (('max_force', max_force), ('stall_timeout', stall_timeout),
                        ('resume_ramp', resume_ramp), ('velocity_cutoff', velocity_cutoff),
                        ('homing_timeout', homing_timeout), ('io_timeout', io_timeout),
                        ('reconnect_period', reconnect_period)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f'{name}: expected a finite number > 0, got {v!r}')
        if not (math.isfinite(gravity_mass) and gravity_mass >= 0):
            raise ValueError(f'gravity_mass: expected a finite number >= 0, got {gravity_mass!r}')
        self.firmware_path, self.device_index, self.serial = firmware_path, device_index, serial
        self.firmware_attempts, self.homing = int(firmware_attempts), bool(homing)
        self.homing_timeout = float(homing_timeout)
        self.gravity_compensation, self.gravity_mass = bool(gravity_compensation), gravity_mass
        self.max_force, self.stall_timeout = float(max_force), float(stall_timeout)
        self.max_motor_command = int(max_motor_command)
        self.resume_ramp, self.velocity_cutoff = float(resume_ramp), float(velocity_cutoff)
        self.disconnect_after, self.reconnect = int(disconnect_after), bool(reconnect)
        self.reconnect_period = float(reconnect_period)
        self.on_disconnect, self.on_reconnect = on_disconnect, on_reconnect
        self.geometry, self.center = geometry, tuple(center)
        self.transport, self.clock, self.sleep = transport, clock, sleep
        self.log = log or _log.info
        self.guard_thread, self.io_timeout = guard_thread, float(io_timeout)
        self.boot_query_tries = int(boot_query_tries)
        self.leds = fp.LED_GREEN
        self.parser = fp.PacketParser()
        self._lock = threading.RLock()
        self._connected = False
        self._lost = False
        self._next_reconnect = 0.0
        self._awaiting_home = False
        self._p = self.center
        self._theta = inverse_kinematics(self.center, geometry)
        self._v = (0.0, 0.0, 0.0)
        self._buttons = (0, 0, 0, 0)
        self._homed = 0
        self._t_reply: float | None = None
        self._last_write: float | None = None
        self._stall_zeroed = False
        self._resume_start: float | None = None
        self._guard_stop = threading.Event()
        self._guard: threading.Thread | None = None
        self._fail_streak = 0
        self._failed_reconnects = 0
        # counters
        self.replies = 0
        self.missed_replies = 0
        self.kinematics_errors = 0
        self.io_errors = 0
        self.stall_events = 0
        self.motor_scaled = 0
        self.disconnects = 0
        self.reconnects = 0
        self.last_command: bytes | None = None
        self.last_error: BaseException | None = None

    # -- connection -------------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        """The USB device is open and answering (False before connect, after close or loss)."""
        return self._connected and not self._lost

    @property
    def disconnected(self) -> bool:
        """The device was lost (unplugged, powered off, no replies) and is not back yet."""
        return self._lost

    @property
    def homed(self) -> bool:
        return self._homed & fp.ALL_HOMED == fp.ALL_HOMED

    def connect(self) -> None:
        """Open the USB device, make sure firmware runs (upload with retries), home; the motors
        are left at zero force. Raises :class:`FalconError` saying what failed."""
        if self._connected:
            return
        firmware = self._read_firmware_file()
        if self.transport is None:
            self.transport = PyFtdiTransport()
        self.transport.open(self.device_index, self.serial)
        self._connected = True
        atexit.register(self.close)
        try:
            self._bring_up(firmware)
            if not self.homed:
                if not self.homing:
                    raise FalconError(
                        'homing is false but the Falcon is not homed (homed flags '
                        f'0b{self._homed:03b} of 0b111): its encoders count from wherever the '
                        'arms were at power-up, so every position would be wrong. Set homing to '
                        'true (then move the grip all the way out and push it straight in), or '
                        'home it with another tool first')
                self._home()
            self._send_zero(self.leds)
            self._start_guard()
        except BaseException:
            self.close()
            raise

    def _bring_up(self, firmware: bytes | None) -> None:
        """Normal mode; firmware running (probe, else upload); replies flowing."""
        self._set_normal_mode()
        if self._probe_firmware():
            self.log('Falcon: firmware already running')
        elif firmware is None:
            raise FalconError(
                'the Falcon runs no firmware (it forgets it at every power-up) and no firmware '
                f'file was given: set the parameter firmware_path to {FIRMWARE_HINT}')
        else:
            self._load_firmware(firmware)

    def _read_firmware_file(self) -> bytes | None:
        if not self.firmware_path:
            return None
        p = Path(self.firmware_path).expanduser()
        try:
            data = p.read_bytes()
        except OSError as exc:
            raise FalconError(f'firmware_path {str(p)!r}: cannot read the firmware file '
                              f'({exc.strerror or exc}); expected {FIRMWARE_HINT}') from None
        if not data:
            raise FalconError(f'firmware_path {str(p)!r}: the file is empty; expected '
                              f'{FIRMWARE_HINT}')
        return data

    def _set_normal_mode(self) -> None:
        """1 ms latency, servo baud rate, then purge both FTDI buffers (libnifalcon's
        setNormalMode): bootloader leftovers must not reach the parser or the device."""
        t = self.transport
        t.set_latency_ms(fp.NORMAL_LATENCY_MS)
        t.set_baudrate(fp.NORMAL_BAUD)
        t.purge()
        self.parser = fp.PacketParser()

    def _read_until(self, done: Callable[[bytes], bool], max_bytes: int,
                    timeout: float) -> bytes:
        """Read until ``done(bytes so far)``, ``max_bytes`` arrived or ``timeout`` s passed."""
        buf = bytearray()
        deadline = self.clock() + timeout
        while len(buf) < max_bytes and not done(bytes(buf)):
            chunk = self.transport.read(max_bytes - len(buf))
            if chunk:
                buf.extend(chunk)
            elif self.clock() > deadline:
                break
            else:
                self.sleep(0.0005)
        return bytes(buf)

    def _read_exact(self, n: int, timeout: float) -> bytes:
        return self._read_until(lambda b: False, n, timeout)

    def _read_reply(self, timeout: float) -> fp.Reply | None:
        """The newest reply arriving within ``timeout`` seconds (None if none)."""
        deadline = self.clock() + timeout
        while True:
            replies = self.parser.feed(self.transport.read(256))
            if replies:
                self._take(replies[-1])
                return replies[-1]
            if self.clock() > deadline:
                return None
            self.sleep(0.0005)

    def _probe_firmware(self, tries: int = 10) -> bool:
        """True when the device answers servo packets (firmware running)."""
        for _ in range(tries):
            self._send(self._packet((0, 0, 0), self.leds))
            if self._read_reply(min(self.io_timeout, 0.02)) is not None:
                return True
        return False

    def _boot_query(self) -> None:
        """Send the bootloader query until it answers ``0a 44 2c 0d`` (libnifalcon tries up to
        100 times); FirmwareError with what came back otherwise."""
        t = self.transport
        ok = (fp.BOOT_QUERY_REPLY, fp.BOOT_QUERY_REPLY_ALT)
        per_try = min(self.io_timeout, 0.05)  # 4 bytes at 9600 baud + the 16 ms latency timer
        seen = []
        for _ in range(self.boot_query_tries):
            t.write(fp.BOOT_QUERY)
            got = self._read_until(lambda b: b in ok, len(fp.BOOT_QUERY_REPLY_ALT), per_try)
            if got in ok:
                return
            if got and len(seen) < 3:
                seen.append(got.hex(' '))
        raise FirmwareError(
            f'the bootloader did not answer its query {fp.BOOT_QUERY.hex(" ")} with '
            f'{fp.BOOT_QUERY_REPLY.hex(" ")} in {self.boot_query_tries} tries'
            + (f' (got {"; ".join(seen)})' if seen else ' (no bytes)'))

    def _upload_once(self, firmware: bytes) -> None:
        """One firmware upload (bootloader handshake, echoed chunks); FirmwareError on failure."""
        t = self.transport
        t.purge()
        t.reset()
        t.set_latency_ms(fp.BOOT_LATENCY_MS)
        t.set_baudrate(fp.BOOT_BAUD)
        t.set_line_8n1()
        t.set_rts(False)
        t.set_dtr(False)
        t.set_dtr(True)
        self._boot_query()
        t.set_dtr(False)
        t.set_baudrate(fp.FIRMWARE_BAUD)
        t.write(fp.FIRMWARE_REQUEST)
        n = len(fp.FIRMWARE_REQUEST_REPLY)
        got = self._read_exact(n, self.io_timeout)
        if got != fp.FIRMWARE_REQUEST_REPLY:
            raise FirmwareError(
                'the bootloader did not enter upload mode (expected the byte '
                f'{fp.FIRMWARE_REQUEST_REPLY.hex()} after {fp.FIRMWARE_REQUEST!r}, got '
                + (got.hex(' ') if got else f'nothing in {self.io_timeout:g} s') + ')')
        for off in range(0, len(firmware), fp.FIRMWARE_CHUNK):
            chunk = firmware[off:off + fp.FIRMWARE_CHUNK]
            t.write(chunk)
            echo = self._read_exact(len(chunk), self.io_timeout)
            if len(echo) < len(chunk):
                raise FirmwareError(f'upload stalled at byte {off + len(echo)} of '
                                    f'{len(firmware)} (no echo)')
            if echo != chunk:
                i = next(k for k in range(len(chunk)) if echo[k] != chunk[k])
                raise FirmwareError(f'echo mismatch at byte {off + i} of {len(firmware)}')
        self._set_normal_mode()
        if not self._probe_firmware():
            raise FirmwareError('uploaded, but the device does not answer servo packets')

    def _load_firmware(self, firmware: bytes) -> None:
        reasons = []
        for attempt in range(1, self.firmware_attempts + 1):
            try:
                self._upload_once(firmware)
                self.log(f'Falcon: firmware {self.firmware_path} loaded (attempt {attempt} of '
                         f'{self.firmware_attempts})')
                return
            except (FirmwareError, OSError) as exc:
                reasons.append(f'attempt {attempt}: {exc}')
                self.log(f'Falcon: firmware upload attempt {attempt} of '
                         f'{self.firmware_attempts} failed: {exc}')
        raise FalconError(
            f'could not load the Falcon firmware {self.firmware_path!r} in '
            f'{self.firmware_attempts} attempt(s) ({"; ".join(reasons)}). Check that the '
            'Falcon\'s power supply is plugged in and on (USB alone does not run it), that the '
            f'file is {FIRMWARE_HINT}, unplug and replug USB and power, and try a larger '
            'firmware_attempts (uploads often fail once or twice)')

    def _home(self) -> None:
        """Until all three arms report homed: LED red, homing bit set (as in every packet), zero
        force; then LED green. Blocks up to ``homing_timeout``."""
        if self.homed:
            return
        self.log('Falcon: homing: move the grip all the way out, then push it straight all the '
                 f'way in (LED red until homed; {self.homing_timeout:g} s)')
        deadline = self.clock() + self.homing_timeout
        while True:
            self._send(self._packet((0, 0, 0), fp.LED_RED))
            reply = self._read_reply(0.01)
            if reply is not None and reply.all_homed:
                break
            if self.clock() > deadline:
                self._send(self._packet((0, 0, 0), fp.LED_RED))
                raise FalconError(
                    f'homing timed out after {self.homing_timeout:g} s (homed flags '
                    f'0b{self._homed:03b} of 0b111): move the grip all the way out, then push it '
                    'straight all the way in; or home it with another tool first')
            self.sleep(0.001)
        self.log('Falcon: homed')

    # -- losing and finding the device -------------------------------------------------------------
    def _failed(self, exc: BaseException | None = None) -> None:
        """One tick without a reply (or an I/O error); enough in a row: the device is lost."""
        if exc is not None:
            self.io_errors += 1
            self.last_error = exc
        self._fail_streak += 1
        if self._fail_streak >= self.disconnect_after and not self._lost:
            why = (f'no reply from the Falcon in {self._fail_streak} consecutive servo ticks'
                   + (f' (last error: {self.last_error})' if self.last_error is not None else '')
                   + ': unplugged or powered off?')
            self._mark_lost(why)

    def _mark_lost(self, why: str) -> None:
        with self._lock:
            self._lost = True
            self.disconnects += 1
            self._v = (0.0, 0.0, 0.0)
            self._next_reconnect = self.clock() + self.reconnect_period
            try:  # a half-working link may still take it
                self.transport.write(self._packet((0, 0, 0), self.leds))
            except Exception:
                pass
            try:
                self.transport.close()
            except Exception:
                pass
        msg = (f'Falcon disconnected: {why}; force zero, velocity zero; '
               + (f'reconnecting every {self.reconnect_period:g} s' if self.reconnect
                  else 'reconnect is off'))
        if self.on_disconnect is not None:  # the hook reports it (the driver logs an error)
            self.on_disconnect(msg)
        else:
            self.log(msg)

    def try_reconnect(self, now: float) -> bool:
        """One attempt to reopen a lost device (firmware reloaded if it lost power); True if it
        is back. Homing, if needed, then happens in the servo ticks (LED red, zero force)."""
        if not self._lost:
            return True
        self._next_reconnect = now + self.reconnect_period
        try:
            firmware = self._read_firmware_file()
            try:
                self.transport.close()
            except Exception:
                pass
            self.transport.open(self.device_index, self.serial)
            self._homed = 0
            self._bring_up(firmware)
        except (OSError, ValueError) as exc:
            self.last_error = exc
            self._failed_reconnects += 1
            if self._failed_reconnects in (1, 10) or self._failed_reconnects % 60 == 0:
                self.log(f'Falcon: reconnect attempt {self._failed_reconnects} failed: {exc}')
            return False
        self._failed_reconnects = 0
        with self._lock:
            self._lost = False
            self._fail_streak = 0
            self._t_reply = None
            self._v = (0.0, 0.0, 0.0)
            self._resume_start = self.clock()
            self._stall_zeroed = False
            self._awaiting_home = not self.homed
            self.reconnects += 1
        msg = ('Falcon reconnected' + ('; not homed: move the grip all the way out, then push '
                                       'it straight in (LED red, no force until homed)'
                                       if self._awaiting_home else ''))
        if self.on_reconnect is not None:
            self.on_reconnect(msg)
        else:
            self.log(msg)
        return True

    # -- guard ------------------------------------------------------------------------------------
    def _start_guard(self) -> None:
        if not self.guard_thread or self._guard is not None:
            return
        self._guard_stop.clear()
        self._guard = threading.Thread(target=self._guard_run, name='falcon-stall-guard',
                                       daemon=True)
        self._guard.start()

    def _guard_run(self) -> None:
        period = self.stall_timeout / 2.0
        while not self._guard_stop.wait(period):
            try:
                self.check_stall()
            except Exception as exc:  # the guard must outlive any one failure
                self.last_error = exc

    def check_stall(self, now: float | None = None) -> bool:
        """Send a zero-force packet if no packet went out for ``stall_timeout``; True if sent.
        Each stall is logged; an I/O error counts towards the disconnect threshold."""
        with self._lock:
            if not self._connected or self._lost or self._stall_zeroed \
                    or self._last_write is None:
                return False
            now = self.clock() if now is None else now
            gap = now - self._last_write
            if gap <= self.stall_timeout:
                return False
            self._stall_zeroed = True
            self.stall_events += 1
            try:
                self._send(self._packet((0, 0, 0), self.leds), stamp=False)
            except OSError as exc:
                self._failed(exc)
        self.log(f'Falcon: servo loop stalled ({gap * 1e3:.1f} ms without a packet > '
                 f'stall_timeout {self.stall_timeout * 1e3:g} ms): sent zero force; the force '
                 f'ramps back over {self.resume_ramp * 1e3:g} ms (stall {self.stall_events})')
        return True

    # -- I/O --------------------------------------------------------------------------------------
    @staticmethod
    def _packet(motors, leds: int) -> bytes:
        """A command packet; the homing bit is set in EVERY packet (a packet without it would
        make the firmware drop the homing; the reference tools keep it set)."""
        return fp.encode_command(motors, leds, homing=True)

    def _send(self, packet: bytes, stamp: bool = True) -> None:
        with self._lock:
            self.transport.write(packet)
            self.last_command = packet
            if stamp:
                self._last_write = self.clock()

    def _send_zero(self, leds: int, stamp: bool = True) -> None:
        self._send(self._packet((0, 0, 0), leds), stamp)

    def _take(self, reply: fp.Reply) -> None:
        """Update the state from one reply (Falcon frame inside)."""
        self.replies += 1
        self._fail_streak = 0
        self._buttons = reply.button_tuple()
        self._homed = reply.homed
        theta = ticks_to_angles(reply.encoders, self.geometry)
        try:
            p = forward_kinematics(theta, guess=self._p, geo=self.geometry)
        except KinematicsError as exc:
            try:  # a jump (first reading, or after a glitch): start again from the centre
                p = forward_kinematics(theta, geo=self.geometry)
            except KinematicsError:
                self.kinematics_errors += 1
                self.last_error = exc
                return
        now = self.clock()
        if self._t_reply is not None and now > self._t_reply:
            dt = now - self._t_reply
            alpha = dt / (dt + 1.0 / (2.0 * math.pi * self.velocity_cutoff))
            self._v = tuple(v + alpha * ((pn - po) / dt - v)
                            for v, pn, po in zip(self._v, p, self._p))
        self._t_reply = now
        self._p, self._theta = p, theta

    # -- Device interface -------------------------------------------------------------------------
    def open(self, now: float) -> None:
        self.connect()
        self._send_zero(self.leds)

    def read(self, now: float) -> DeviceState:
        if self._lost:
            if self.reconnect and now >= self._next_reconnect:
                self.try_reconnect(now)
        elif self._connected:
            try:
                with self._lock:
                    data = self.transport.read(256)
                replies = self.parser.feed(data)
            except OSError as exc:
                self.missed_replies += 1
                self._failed(exc)
                replies = []
            else:
                if replies:
                    self._take(replies[-1])
                else:
                    self.missed_replies += 1
                    self._failed()
        c = self.center
        pos = falcon_to_device((self._p[0] - c[0], self._p[1] - c[1], self._p[2] - c[2]))
        v = (0.0, 0.0, 0.0) if self._lost else falcon_to_device(self._v)
        return DeviceState(pos, v, self._buttons)

    def tip_force(self, force) -> tuple[float, float, float]:
        """The tip force [N], Falcon frame, sent for a device-frame command ``force``: finite
        or zero, clamped to max_force, gravity compensation added, total clamped again."""
        try:
            f = tuple(float(v) for v in force)
        except (TypeError, ValueError):
            f = (0.0, 0.0, 0.0)
        if len(f) != 3 or not all(map(math.isfinite, f)):
            f = (0.0, 0.0, 0.0)
        f = _clamp(device_to_falcon(f), self.max_force)
        if self.gravity_compensation and self.gravity_mass > 0:
            g = gravity_force(self.gravity_mass)
            f = _clamp((f[0] + g[0], f[1] + g[1], f[2] + g[2]), self.max_force)
        return f

    def motor_commands(self, f) -> tuple[int, int, int]:
        """Motor command counts for the tip force ``f`` (3,) [N], Falcon frame, at the current
        pose: ``J^T f`` torques in counts, all three scaled by one factor when the largest exceeds
        ``max_motor_command`` (the force keeps its direction and gets shorter)."""
        if f == (0.0, 0.0, 0.0):
            return (0, 0, 0)
        tau = force_to_torque(self._p, f, theta=self._theta, geo=self.geometry)
        cmds = torques_to_commands(tau, self.geometry)
        peak = max(abs(c) for c in cmds)
        if peak > self.max_motor_command:
            k = self.max_motor_command / peak
            cmds = tuple(c * k for c in cmds)
            self.motor_scaled += 1
        return tuple(fp.saturate_int16(c) for c in cmds)

    def write(self, force) -> None:
        if not self._connected or self._lost:
            return  # nothing to send to: a lost device gets zero when it comes back
        f = self.tip_force(force)
        now = self.clock()
        with self._lock:
            leds = self.leds
            if self._awaiting_home:  # after a reconnect: home first, no force meanwhile
                if self.homed:
                    self._awaiting_home = False
                    self._resume_start = now
                    self.log('Falcon: homed')
                else:
                    f, leds = (0.0, 0.0, 0.0), fp.LED_RED
            if self._stall_zeroed:
                self._stall_zeroed = False
                self._resume_start = now
            if self._resume_start is not None:
                k = (now - self._resume_start) / self.resume_ramp
                if k >= 1.0:
                    self._resume_start = None
                else:
                    f = _clamp(f, self.max_force * max(k, 0.0))
            try:
                cmds = self.motor_commands(f)
            except KinematicsError as exc:  # singular pose: no force rather than a wrong one
                self.kinematics_errors += 1
                self.last_error = exc
                cmds = (0, 0, 0)
            try:
                self._send(self._packet(cmds, leds))
            except OSError as exc:
                self._failed(exc)

    def close(self) -> None:
        """Stop the guard, send zero force, close USB. Safe to call twice (also runs at exit)."""
        self._guard_stop.set()
        if self._guard is not None and self._guard is not threading.current_thread():
            self._guard.join(1.0)
        self._guard = None
        with self._lock:
            if not self._connected:
                return
            if not self._lost:
                try:
                    self._send(self._packet((0, 0, 0), 0))
                except Exception as exc:  # nothing more can be done for a vanished device
                    self.last_error = exc
                try:
                    self.transport.close()
                except Exception as exc:
                    self.last_error = exc
            self._connected = False
        atexit.unregister(self.close)


def _clamp(f, limit: float):
    n = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
    if n > limit:
        s = limit / n if n > 0 else 0.0
        return (f[0] * s, f[1] * s, f[2] * s)
    return f
