"""A fake Novint Falcon behind a fake ``pyftdi.ftdi.Ftdi`` (no hardware, no USB library).

Written from the reference's documented protocol, NOT from haptic_anfis's own encoder: it
imports nothing from ``haptic_anfis`` and has its own packet code, so a test fails where our
code and the real device disagree. Sources (public, described not copied):

- libnifalcon ``FalconCommLibUSB::setFirmwareMode`` / ``setNormalMode`` and
  ``FalconFirmware::loadFirmware``: the bootloader is entered by toggling DTR low -> high at
  9600 baud; it answers the query ``0a 43 0d`` with ``0a 44 2c 0d`` but often not the first time
  (the reference sends it up to 100 times); at 140000 baud ``'A'`` is answered by ONE byte 0x41
  (libnifalcon reads 3 bytes over raw libusb = 2 FTDI status bytes + 0x41; pyftdi strips the
  status bytes); the firmware is then echoed byte for byte. Afterwards 1456312 baud, and both
  buffers are purged.
- libnifalcon ``FalconFirmwareNovintSDK::formatInput`` / ``formatOutput``: 16-byte packets
  ``'<'`` + 14 bytes + ``'>'``; each byte is ``0x41 + nibble``; three signed 16-bit values, least
  significant nibble first (motor commands out, encoder counts back); byte 13: LEDs | homing-mode
  bit 0x01 out, grip buttons (bits 0-3) | homed flags (bits 4-6) back. One reply per command.
- libnifalcon's ``findfalcons`` and ros_falcon: homing mode is set once and left set; the encoders
  count from wherever the arms were at power-up until the arms are homed (grip all the way out,
  then in). This model drops the homing whenever a packet arrives without the homing bit.
- The device needs its power supply to run the microcontroller (USB alone powers only the FTDI
  chip) and forgets its firmware when power goes. pyftdi raises ``usb.core.USBError`` (an
  OSError) on every call once the device is unplugged.
"""
from __future__ import annotations

import errno
import mmap
import time
from dataclasses import dataclass

import numpy as np

VENDOR_ID, PRODUCT_ID = 0x0403, 0xCB48
BOOT_BAUD, UPLOAD_BAUD, SERVO_BAUD = 9600, 140_000, 1_456_312
USB_PAYLOAD = 62  # 64-byte full-speed packet less the FTDI's 2 status bytes


@dataclass(frozen=True)
class Received:
    """One command packet as the device decoded it."""
    motors: tuple[int, int, int]
    leds: int
    homing: bool


class Unplugged(OSError):
    """What pyftdi/pyusb raise for a vanished device (usb.core.USBError is an OSError)."""

    def __init__(self):
        super().__init__(errno.ENODEV, 'No such device (it may have been disconnected)')


def _nibbles(value: int) -> bytes:
    u = value & 0xFFFF
    return bytes(0x41 + ((u >> (4 * k)) & 0xF) for k in range(4))


def _from_nibbles(b: bytes) -> int:
    u = 0
    for k in range(4):
        u |= ((b[k] - 0x41) & 0xF) << (4 * k)
    return u - 0x10000 if u & 0x8000 else u


class FakeFalcon:
    """The device: FTDI line settings, bootloader, firmware, arms, grip, homing, power, cable.

    Args:
        firmware_running: firmware already loaded (e.g. by another tool since power-up).
        expected_firmware: the image the bootloader accepts (None: any non-empty upload).
        boot_query_ignored: bootloader queries ignored before it answers (per upload attempt).
        corrupt_echo_at: flip this byte of the echoed upload (a line error).
        encoders: true arm positions [ticks], as a homed device reports them.
        powerup_offset: where the arms were at power-up [ticks]: until homed the encoders read
            ``encoders - powerup_offset``.
        homed: all three arms homed already.
        homes_after: homing-mode packets the user needs to home the arms (the out-and-in move).
        buttons: grip buttons (4 bits).
        max_read: bytes per read (cut the stream anywhere).
        powered: the power supply is on.
    """

    #: what the bootloader answers to its query (a subclass may model another device)
    BOOT_REPLY = bytes((0x0A, 0x44, 0x2C, 0x0D))

    def __init__(self, firmware_running: bool = False, expected_firmware: bytes | None = None,
                 boot_query_ignored: int = 2, corrupt_echo_at: int | None = None,
                 encoders=(0, 0, 0), powerup_offset=(0, 0, 0), homed: bool = True,
                 homes_after: int = 0, buttons: int = 0, max_read: int | None = None,
                 garbage: bytes = b'', powered: bool = True):
        self.firmware_running = firmware_running
        self.expected_firmware = expected_firmware
        self.boot_query_ignored = self._ignore = boot_query_ignored
        self.corrupt_echo_at = corrupt_echo_at
        self.encoders = tuple(encoders)
        self.powerup_offset = tuple(powerup_offset)
        self.homed_flags = 0x7 if homed else 0
        self.homes_after = homes_after
        self.buttons = buttons
        self.max_read = max_read
        self.garbage = garbage                       # sent before every reply
        self.powered, self.plugged = powered, True
        self.present = True                          # on the bus (find_all)
        self.replying = True                         # False: a hung firmware
        self.mode = 'normal' if firmware_running else 'idle'
        self.baud = self.latency = self.dtr = self.rts = None
        self.uploaded = bytearray()
        self.rx = bytearray()                        # device -> host
        self._tx = bytearray()                       # host -> device, not yet a whole packet
        self.commands: list[Received] = []           # every command packet decoded
        self.write_times: list[float] = []           # time.monotonic() of each command packet
        self.calls: list[tuple] = []
        self.boot_replies = 0
        self.upload_writes: list[int] = []           # size of each write during the upload
        self.homing_dropped = 0                      # packets that cleared the homing
        self.open_args = None
        self.closed = False

    # -- what the host sees -------------------------------------------------------------------------
    @property
    def homed(self) -> bool:
        return self.homed_flags == 0x7

    def reported_encoders(self) -> tuple[int, int, int]:
        if self.homed:
            return self.encoders
        return tuple(e - o for e, o in zip(self.encoders, self.powerup_offset))

    # -- the user's hands ---------------------------------------------------------------------------
    def unplug(self) -> None:
        self.plugged = self.present = False

    def replug(self, power_cycled: bool = True) -> None:
        """Cable back in; with ``power_cycled`` the device lost power: firmware and homing gone."""
        self.plugged = self.present = True
        self.rx.clear()
        self._tx.clear()
        if power_cycled:
            self.firmware_running = False
            self.mode = 'idle'
            self.homed_flags = 0

    def _check(self):
        if not self.plugged:
            raise Unplugged()

    # -- FTDI line settings -------------------------------------------------------------------------
    def set_baudrate(self, baud):
        self._check()
        self.baud = baud
        self.calls.append(('baud', baud))
        if baud == SERVO_BAUD and self.mode == 'upload':
            ok = (bytes(self.uploaded) == self.expected_firmware
                  if self.expected_firmware is not None else bool(self.uploaded))
            self.firmware_running = ok and self.powered
            self.mode = 'normal' if self.firmware_running else 'idle'
            # bytes the bootloader sent while the line changed speed: purge them
            self.rx += b'\x00\xfe'

    def set_dtr(self, state):
        self._check()
        # DTR low -> high at 9600 baud resets the microcontroller into its bootloader.
        if state and self.dtr is False and self.baud == BOOT_BAUD and self.powered:
            self.mode = 'boot_query'
            self.firmware_running = False
            self._ignore = self.boot_query_ignored
        self.dtr = state

    # -- bytes --------------------------------------------------------------------------------------
    def write(self, data: bytes) -> int:
        self._check()
        data = bytes(data)
        if not self.powered:
            return len(data)  # the FTDI chip takes it; nobody behind it answers
        if self.mode == 'boot_query':
            if data == bytes((0x0A, 0x43, 0x0D)) and self.baud == BOOT_BAUD:
                if self._ignore > 0:
                    self._ignore -= 1
                else:
                    self.rx += self.BOOT_REPLY
                    self.boot_replies += 1
                    if self.BOOT_REPLY == bytes((0x0A, 0x44, 0x2C, 0x0D)):
                        self.mode = 'boot_request'
        elif self.mode == 'boot_request':
            if data == b'A' and self.baud == UPLOAD_BAUD and not self.dtr:
                self.rx += b'\x41'
                self.mode = 'upload'
                self.uploaded.clear()
        elif self.mode == 'upload':
            self.upload_writes.append(len(data))
            echo = bytearray(data)
            i = self.corrupt_echo_at
            if i is not None and len(self.uploaded) <= i < len(self.uploaded) + len(data):
                echo[i - len(self.uploaded)] ^= 0xFF
            self.uploaded += data
            self.rx += echo
        elif self.mode == 'normal' and self.firmware_running and self.baud == SERVO_BAUD:
            self._tx += data
            self._servo()
        return len(data)

    def _servo(self) -> None:
        while True:
            start = self._tx.find(b'<')
            if start < 0:
                self._tx.clear()
                return
            del self._tx[:start]
            if len(self._tx) < 16:
                return
            pkt = bytes(self._tx[:16])
            del self._tx[:16]
            if pkt[15] != ord('>') or not all(0x41 <= b <= 0x50 for b in pkt[1:15]):
                continue  # the firmware ignores a malformed packet
            motors = tuple(_from_nibbles(pkt[1 + 4 * i:5 + 4 * i]) for i in range(3))
            flags = pkt[13] - 0x41
            cmd = Received(motors, flags & 0xE, bool(flags & 0x1))
            self.commands.append(cmd)
            self.write_times.append(time.monotonic())
            if cmd.homing:
                if not self.homed:
                    if self.homes_after <= 0:
                        self.homed_flags = 0x7
                    self.homes_after -= 1
            elif self.homed_flags:
                self.homed_flags = 0  # homing mode off: the firmware drops the homing
                self.homing_dropped += 1
            if self.replying:
                self.rx += self.garbage + self._reply()

    def _reply(self) -> bytes:
        out = bytearray(b'<')
        for e in self.reported_encoders():
            out += _nibbles(int(e))
        out.append(0x41 + ((self.buttons & 0xF) | (self.homed_flags << 4)))
        out.append(0x41)
        out += b'>'
        return bytes(out)

    def read(self, size: int) -> bytes:
        self._check()
        n = min(size, len(self.rx), USB_PAYLOAD if self.max_read is None else self.max_read)
        out = bytes(self.rx[:n])
        del self.rx[:n]
        return out


class FakeFtdi:
    """The slice of ``pyftdi.ftdi.Ftdi`` that PyFtdiTransport uses."""
    device: FakeFalcon = None
    custom_products: list = []

    @classmethod
    def add_custom_product(cls, vid, pid, pidname=''):
        if (vid, pid) in cls.custom_products:
            raise ValueError('already registered')
        cls.custom_products.append((vid, pid))

    @classmethod
    def find_all(cls, vps, nocache=False):
        class Desc:
            sn = 'FAKE0001'
        return [(Desc(), 1)] if cls.device.present else []

    def open(self, vendor, product, bus=None, address=None, index=0, serial=None, interface=1):
        d = self.device
        if not d.present or index != 0 or serial not in (None, 'FAKE0001'):
            raise OSError('No USB device matches URL')
        assert (vendor, product) == (VENDOR_ID, PRODUCT_ID)
        d.open_args = (index, serial)
        d.closed = False
        d.calls.append(('open',))

    def close(self, freeze=False):
        self.device.closed = True

    def purge_buffers(self):
        self.device._check()
        self.device.rx.clear()
        self.device._tx.clear()
        self.device.calls.append(('purge',))

    def reset(self, usb_reset=False):
        self.device._check()
        self.device.calls.append(('reset',))

    def set_latency_timer(self, latency):
        self.device._check()
        self.device.latency = latency

    def set_baudrate(self, baudrate, constrain=True):
        self.device.set_baudrate(baudrate)
        return baudrate

    def set_line_property(self, bits, stopbit, parity, break_=False):
        self.device._check()
        self.device.calls.append(('line', bits, stopbit, parity))

    def set_flowctrl(self, flowctrl):
        self.device._check()
        self.device.calls.append(('flow', flowctrl))

    def set_rts(self, state):
        self.device._check()
        self.device.rts = state

    def set_dtr(self, state):
        self.device.set_dtr(state)

    def write_data(self, data):
        return self.device.write(data)

    def read_data_bytes(self, size, attempt=1, request_gen=None):
        return bytearray(self.device.read(size))


def ftdi_class(device: FakeFalcon):
    """A fake ``Ftdi`` class talking to ``device``."""
    return type('FakeFtdi', (FakeFtdi,), {'device': device, 'custom_products': []})


class Clock:
    """A fake monotonic clock for the backend's ``clock`` / ``sleep`` hooks: time [s] moves only
    when the code under test sleeps (at least 0.1 ms per sleep), so the tests never wait."""

    def __init__(self, t: float = 100.0):
        self.t = t

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += max(dt, 1e-4)


# shared slots: commands received, last motors (3), closed, plugged
N, M0, CLOSED, PLUGGED = 0, 1, 4, 5


class SharedFake(FakeFalcon):
    """A FakeFalcon whose received commands, closed flag and cable are in ``shm`` (float64), so
    another process (the test, across the fork) sees them and can pull the cable."""

    def __init__(self, shm: np.ndarray, **kw):
        self._shm = shm
        super().__init__(**kw)
        self.commands = _Commands(shm)

    plugged = property(lambda s: bool(s._shm[PLUGGED]),
                       lambda s, v: s._shm.__setitem__(PLUGGED, float(v)))
    present = property(lambda s: bool(s._shm[PLUGGED]), lambda s, v: None)
    closed = property(lambda s: bool(s._shm[CLOSED]),
                      lambda s, v: s._shm.__setitem__(CLOSED, float(v)))


class _Commands(list):
    def __init__(self, shm):
        super().__init__()
        self._shm = shm

    def append(self, cmd) -> None:
        if len(self) > 1000:
            del self[:500]  # bounded: only the shared slots are read
        super().append(cmd)
        self._shm[M0:M0 + 3] = cmd.motors
        self._shm[N] += 1


def shared(n: int = 8) -> np.ndarray:
    return np.frombuffer(mmap.mmap(-1, 8 * n), dtype=np.float64)
