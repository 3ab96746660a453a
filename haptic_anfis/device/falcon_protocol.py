"""The Novint Falcon's USB wire protocol: constants, packet encoding and decoding (pure, no I/O).

Everything here is integers and bytes: encoder ticks, signed 16-bit motor commands, LED and
button bit fields. Conversion to SI units (rad, N m) lives in :mod:`.falcon_kinematics`; the
transport that moves these bytes lives in :mod:`.falcon_usb`.

Sources (public; written from their descriptions, no code copied): libnifalcon (BSD, K. Machulis,
Nonpolynomial Labs) — ``FalconFirmwareNovintSDK`` for the packet layout, ``FalconCommLibFTDI`` for
the bootloader handshake and serial settings, ``FalconFirmware`` for LED/homing flags; the
nonpolynomial.com Novint Falcon protocol notes those files refer to. None of it has been checked
against a real Falcon here.

The device
    An FTDI USB-serial bridge with the vendor/product id :data:`VENDOR_ID`/:data:`PRODUCT_ID`
    in front of a microcontroller whose RAM firmware must be uploaded after every power-up (the
    "Novint SDK" firmware, distributed with Novint's drivers and with libnifalcon's sources; we
    ship none).

Bootloader handshake (firmware upload), as libnifalcon's libusb back end does it
(``FalconCommLibUSB::setFirmwareMode`` / ``setNormalMode``, ``FalconFirmware::loadFirmware``)
    purge, reset, latency timer 16 ms, 9600 baud 8N1 no flow control, RTS low, DTR low then
    high; send :data:`BOOT_QUERY` until the bootloader answers exactly :data:`BOOT_QUERY_REPLY`
    (up to :data:`BOOT_QUERY_TRIES` times: it often ignores the first ones); DTR low,
    :data:`FIRMWARE_BAUD` baud; send ``b'A'`` and expect ONE byte back, :data:`FIRMWARE_REQUEST_REPLY`
    (0x41). The FTDI chip prefixes every USB read with two modem-status bytes: libnifalcon's libusb
    code reads 3 bytes and checks the third; pyftdi strips the status bytes, so we see one. (The
    older libftdi back end's comment says "0x13 0x41", two bytes, but never checks them.) Then the
    firmware file goes in chunks of :data:`FIRMWARE_CHUNK` (62) bytes, each echoed back byte for
    byte. Afterwards "normal mode": latency timer 1 ms, :data:`NORMAL_BAUD` baud, and both FTDI
    buffers purged (left-over bootloader bytes must not reach the packet parser or the device).

Normal-mode packets (both directions 16 bytes)
    ``'<'``, 14 payload bytes, ``'>'``. Every payload byte carries a value ``v`` as ``0x41 + v``
    ('A' + v); multi-byte numbers are sent one 4-bit nibble per byte, least significant first.

    host -> device (:func:`encode_command`)
        bytes 1-4, 5-8, 9-12: motor 1, 2, 3 command, signed 16-bit, 4 nibbles each;
        byte 13: LED bits (:data:`LED_GREEN`, :data:`LED_BLUE`, :data:`LED_RED`) | homing-mode
        bit (:data:`HOMING_MODE`); byte 14: 0. The homing bit is not a one-off request: the
        reference tools set it once and leave it set in every later packet (libnifalcon's
        ``setHomingMode(true)`` is sticky; ros_falcon and libnifalcon's examples never clear it,
        "keep track of encoders, needed"); a host that clears it after homing loses the homing.
    device -> host (:func:`decode_reply`)
        bytes 1-12: encoder 1, 2, 3, signed 16-bit ticks, 4 nibbles each;
        byte 13: value = grip buttons (bits 0-3) | per-motor "homed" flags (bits 4-6);
        byte 14: unused here.

    The device answers each command packet with one reply packet: a host writes one command per
    servo tick and reads the reply to the previous one.
"""
from __future__ import annotations

from dataclasses import dataclass
from ..errors import HapticAnfisError

#: FTDI vendor id, and the product id the Falcon's FTDI chip reports.
VENDOR_ID = 0x0403
PRODUCT_ID = 0xCB48

PACKET_SIZE = 16
START, END = 0x3C, 0x3E  # '<', '>'
NIBBLE_BASE = 0x41       # 'A': payload byte = NIBBLE_BASE + value

#: Command byte 13 flags.
HOMING_MODE = 0x1
LED_GREEN, LED_BLUE, LED_RED = 0x2, 0x4, 0x8
LED_MASK = LED_GREEN | LED_BLUE | LED_RED

#: Reply byte 13: buttons in bits 0-3, homed flags (motor 1, 2, 3) in bits 4-6.
BUTTON_MASK = 0x0F
HOMED_SHIFT = 4
ALL_HOMED = 0x7

INT16_MIN, INT16_MAX = -0x8000, 0x7FFF

#: Bootloader / firmware-upload settings (see the module docstring).
BOOT_BAUD = 9600
BOOT_LATENCY_MS = 16
BOOT_QUERY = bytes((0x0A, 0x43, 0x0D))
BOOT_QUERY_REPLY = bytes((0x0A, 0x44, 0x2C, 0x0D))
#: libnifalcon's libusb back end also accepts the reply behind one 0x00 byte (macOS).
BOOT_QUERY_REPLY_ALT = b'\x00' + BOOT_QUERY_REPLY
BOOT_QUERY_TRIES = 100
FIRMWARE_BAUD = 140_000
FIRMWARE_REQUEST = b'A'
FIRMWARE_REQUEST_REPLY = b'\x41'
#: 64-byte full-speed USB packets less the FTDI's 2 status bytes (libnifalcon's READ_SIZE).
FIRMWARE_CHUNK = 62
#: Normal (servo) mode settings.
NORMAL_BAUD = 1_456_312
NORMAL_LATENCY_MS = 1


class PacketError(HapticAnfisError, ValueError):
    """A byte string that is not a well-formed Falcon packet."""


@dataclass(frozen=True)
class Command:
    """A host -> device packet: motor commands (3 signed 16-bit ints), LED bits, homing request."""
    motors: tuple[int, int, int] = (0, 0, 0)
    leds: int = 0
    homing: bool = False


@dataclass(frozen=True)
class Reply:
    """A device -> host packet: encoder ticks (3 signed 16-bit ints), button bits (0-3), homed
    flags per motor (bit i = motor i+1 homed)."""
    encoders: tuple[int, int, int]
    buttons: int = 0
    homed: int = 0

    @property
    def all_homed(self) -> bool:
        return self.homed & ALL_HOMED == ALL_HOMED

    def button_tuple(self) -> tuple[int, int, int, int]:
        """Buttons as four 0/1 values (bit 0 first)."""
        return tuple((self.buttons >> i) & 1 for i in range(4))


def saturate_int16(v: float) -> int:
    """``v`` rounded to the nearest integer and clipped to the signed 16-bit range."""
    if v != v:  # NaN never reaches a motor
        return 0
    return int(min(max(round(v), INT16_MIN), INT16_MAX))


def _put_int16(out: bytearray, value: int) -> None:
    if not INT16_MIN <= value <= INT16_MAX:
        raise PacketError(f'value {value} outside the signed 16-bit range')
    u = value & 0xFFFF
    for k in range(4):
        out.append(NIBBLE_BASE + ((u >> (4 * k)) & 0xF))


def _get_nibble(packet, i: int) -> int:
    v = packet[i] - NIBBLE_BASE
    if not 0 <= v <= 0xF:
        raise PacketError(f'byte {i} = 0x{packet[i]:02x} is not a nibble (0x41..0x50)')
    return v


def _get_int16(packet, i: int) -> int:
    u = 0
    for k in range(4):
        u |= _get_nibble(packet, i + k) << (4 * k)
    return u - 0x10000 if u & 0x8000 else u


def _check_frame(packet) -> None:
    if len(packet) != PACKET_SIZE:
        raise PacketError(f'expected {PACKET_SIZE} bytes, got {len(packet)}')
    if packet[0] != START or packet[-1] != END:
        raise PacketError("a packet starts with '<' and ends with '>'")


def encode_command(motors=(0, 0, 0), leds: int = 0, homing: bool = False) -> bytes:
    """The 16-byte command packet. ``motors``: three signed 16-bit ints (use
    :func:`saturate_int16` first); ``leds``: a combination of the LED_* bits."""
    if len(motors) != 3:
        raise PacketError(f'expected 3 motor commands, got {len(motors)}')
    if leds & ~LED_MASK:
        raise PacketError(f'LED bits 0x{leds:x} outside 0x{LED_MASK:x}')
    out = bytearray((START,))
    for m in motors:
        _put_int16(out, int(m))
    out.append(NIBBLE_BASE + (leds | (HOMING_MODE if homing else 0)))
    out.append(NIBBLE_BASE)
    out.append(END)
    return bytes(out)


def decode_command(packet) -> Command:
    """Inverse of :func:`encode_command` (what a device, or a test's fake device, reads)."""
    _check_frame(packet)
    motors = tuple(_get_int16(packet, 1 + 4 * i) for i in range(3))
    flags = _get_nibble(packet, 13)
    _get_nibble(packet, 14)
    return Command(motors, flags & LED_MASK, bool(flags & HOMING_MODE))


def encode_reply(encoders, buttons: int = 0, homed: int = 0) -> bytes:
    """The 16-byte reply packet a Falcon sends (for fake devices and recorded streams)."""
    if len(encoders) != 3:
        raise PacketError(f'expected 3 encoder values, got {len(encoders)}')
    if buttons & ~BUTTON_MASK or homed & ~ALL_HOMED:
        raise PacketError(f'buttons 0x{buttons:x} or homed 0x{homed:x} out of range')
    out = bytearray((START,))
    for e in encoders:
        _put_int16(out, int(e))
    out.append(NIBBLE_BASE + (buttons | (homed << HOMED_SHIFT)))
    out.append(NIBBLE_BASE)
    out.append(END)
    return bytes(out)


def decode_reply(packet) -> Reply:
    """Encoders, buttons and homed flags of one 16-byte reply packet; :class:`PacketError` if
    it is malformed."""
    _check_frame(packet)
    encoders = tuple(_get_int16(packet, 1 + 4 * i) for i in range(3))
    v = packet[13] - NIBBLE_BASE
    if not 0 <= v <= (BUTTON_MASK | (ALL_HOMED << HOMED_SHIFT)):
        raise PacketError(f'byte 13 = 0x{packet[13]:02x} out of range')
    return Reply(encoders, v & BUTTON_MASK, (v >> HOMED_SHIFT) & ALL_HOMED)


class PacketParser:
    """Reassembles reply packets from a byte stream cut anywhere (USB reads return whatever
    arrived). Bytes before a ``'<'`` and malformed packets are dropped and counted, and the
    parser resynchronises on the next ``'<'``."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.packets = 0
        self.dropped_bytes = 0
        self.malformed = 0

    def feed(self, data) -> list[Reply]:
        """Add ``data``; return the complete replies it finished, oldest first."""
        buf = self._buf
        buf.extend(data)
        out: list[Reply] = []
        while True:
            start = buf.find(START)
            if start < 0:
                self.dropped_bytes += len(buf)
                buf.clear()
                break
            if start:
                self.dropped_bytes += start
                del buf[:start]
            if len(buf) < PACKET_SIZE:
                # A '>' before a full packet means this one is truncated: drop up to it.
                end = buf.find(END, 1)
                if end >= 0:
                    self.malformed += 1
                    self.dropped_bytes += end + 1
                    del buf[:end + 1]
                    continue
                break
            try:
                out.append(decode_reply(bytes(buf[:PACKET_SIZE])))
                self.packets += 1
                del buf[:PACKET_SIZE]
            except PacketError:
                self.malformed += 1
                self.dropped_bytes += 1
                del buf[:1]  # resynchronise on the next '<'
        return out
