"""A fake Novint Falcon behind a fake ``pyftdi.ftdi.Ftdi`` (no hardware, no USB library).

:class:`FakeFalcon` is the device: bootloader handshake, firmware upload with echo, and in normal
mode one reply packet per command packet, from its encoder ticks, buttons and homed flags.
:func:`ftdi_class` returns a class with the methods of ``pyftdi.ftdi.Ftdi`` that
:class:`haptic_anfis.device.falcon_usb.PyFtdiTransport` calls, wired to one FakeFalcon. Built
from the protocol description in :mod:`haptic_anfis.device.falcon_protocol`, not from a device.
"""
from __future__ import annotations

from haptic_anfis.device import falcon_protocol as fp


class FakeFalcon:
    def __init__(self, firmware_running: bool = False, expected_firmware: bytes | None = None,
                 boot_failures: int = 0, corrupt_echo_at: int | None = None,
                 encoders=(0, 0, 0), buttons: int = 0, homed: int = fp.ALL_HOMED,
                 homes_after: int = 0, max_read: int | None = None, garbage: bytes = b'',
                 present: bool = True):
        self.firmware_running = firmware_running
        self.expected_firmware = expected_firmware
        self.boot_failures = boot_failures          # bootloader queries left unanswered
        self.corrupt_echo_at = corrupt_echo_at      # flip this byte of the echoed upload
        self.encoders, self.buttons, self.homed = tuple(encoders), buttons, homed
        self.homes_after = homes_after              # homing packets until all arms are homed
        self.max_read = max_read                    # bytes per read (cut the stream anywhere)
        self.garbage = garbage                      # sent before every reply
        self.present = present
        self.mode = 'normal'
        self.baud = None
        self.latency = None
        self.dtr = self.rts = None
        self.uploaded = bytearray()
        self.rx = bytearray()                       # device -> host
        self.commands: list[fp.Command] = []        # every servo packet received
        self.calls: list[tuple] = []
        self.open_args = None
        self.closed = False
        self.replying = True                        # False: swallow packets (a hung device)
        self._pending = bytearray()

    # host-side events
    def set_baudrate(self, baud):
        self.baud = baud
        if baud == fp.NORMAL_BAUD and self.mode == 'upload':
            self.firmware_running = (bytes(self.uploaded) == self.expected_firmware
                                     if self.expected_firmware is not None
                                     else bool(self.uploaded))
            self.mode = 'normal'

    def set_dtr(self, state):
        if state and self.dtr is False and self.baud == fp.BOOT_BAUD:
            self.mode = 'boot_query'
            self.firmware_running = False
        self.dtr = state

    def write(self, data: bytes):
        data = bytes(data)
        if self.mode == 'boot_query' and data == fp.BOOT_QUERY:
            if self.boot_failures > 0:
                self.boot_failures -= 1
            else:
                self.rx += bytes((0x0A, 0x44, 0x2C, 0x0D))
                self.mode = 'boot_request'
        elif self.mode == 'boot_request' and data == fp.FIRMWARE_REQUEST \
                and self.baud == fp.FIRMWARE_BAUD:
            self.rx += bytes((0x13, 0x41))
            self.mode = 'upload'
            self.uploaded.clear()
        elif self.mode == 'upload':
            echo = bytearray(data)
            i = self.corrupt_echo_at
            if i is not None and len(self.uploaded) <= i < len(self.uploaded) + len(data):
                echo[i - len(self.uploaded)] ^= 0xFF
            self.uploaded += data
            self.rx += echo
        elif self.mode == 'normal' and self.firmware_running:
            self._pending += data
            while len(self._pending) >= fp.PACKET_SIZE:
                pkt = bytes(self._pending[:fp.PACKET_SIZE])
                del self._pending[:fp.PACKET_SIZE]
                cmd = fp.decode_command(pkt)
                self.commands.append(cmd)
                if cmd.homing and self.homed != fp.ALL_HOMED:
                    if self.homes_after <= 0:
                        self.homed = fp.ALL_HOMED
                    self.homes_after -= 1
                if self.replying:
                    self.rx += self.garbage + fp.encode_reply(self.encoders, self.buttons,
                                                              self.homed)
        return len(data)

    def read(self, size):
        n = min(size, len(self.rx))
        if self.max_read is not None:
            n = min(n, self.max_read)
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
        assert (vendor, product) == (fp.VENDOR_ID, fp.PRODUCT_ID)
        d.open_args = (index, serial)
        d.calls.append(('open',))

    def close(self, freeze=False):
        self.device.closed = True

    def purge_buffers(self):
        self.device.rx.clear()
        self.device.calls.append(('purge',))

    def reset(self, usb_reset=False):
        self.device.calls.append(('reset',))

    def set_latency_timer(self, latency):
        self.device.latency = latency

    def set_baudrate(self, baudrate, constrain=True):
        self.device.set_baudrate(baudrate)
        return baudrate

    def set_line_property(self, bits, stopbit, parity, break_=False):
        self.device.calls.append(('line', bits, stopbit, parity))

    def set_flowctrl(self, flowctrl):
        self.device.calls.append(('flow', flowctrl))

    def set_rts(self, state):
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
