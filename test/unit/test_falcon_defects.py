"""Issue 19: what would stop or mislead the Falcon backend on a real device, one test (or more)
per defect, against the fake built from libnifalcon's documented protocol (falcon_fake.py).
Each of these failed on the code before the fix."""
from __future__ import annotations

import dataclasses
import math

import pytest
from falcon_fake import Clock, FakeFalcon, ftdi_class

from haptic_anfis.device import falcon_kinematics as k
from haptic_anfis.device import falcon_protocol as fp
from haptic_anfis.device import falcon_usb
from haptic_anfis.device.falcon_usb import FalconError, FalconUSB, PyFtdiTransport
from tick_oracle import SafetyLayer, ServoLoop

FIRMWARE = bytes(range(256)) * 4 + b'end'  # 1027 bytes: 16 chunks of 62 and a short one


def make(fake, firmware=None, tmp_path=None, clock=None, **kw):
    path = ''
    if firmware is not None:
        path = str(tmp_path / 'nvent_firmware.bin')
        (tmp_path / 'nvent_firmware.bin').write_bytes(firmware)
    clock = clock or Clock()
    logs = []
    dev = FalconUSB(firmware_path=path, transport=PyFtdiTransport(ftdi_class(fake)), clock=clock,
                    sleep=clock.sleep, log=logs.append, guard_thread=False, **kw)
    dev.logs = logs
    return dev


def ticks_at(p):
    return k.angles_to_ticks(k.inverse_kinematics(p))


def tip_force(dev, fake):
    return k.torque_to_force(dev._p, k.commands_to_torques(fake.commands[-1].motors))


# -- 1. firmware load --------------------------------------------------------------------------------
def test_firmware_loads_into_a_freshly_powered_falcon_in_one_attempt(tmp_path):
    """The bootloader ignores its first queries and answers 'A' with ONE byte (0x41)."""
    fake = FakeFalcon(expected_firmware=FIRMWARE, boot_query_ignored=7)
    dev = make(fake, FIRMWARE, tmp_path, firmware_attempts=1, io_timeout=0.05)
    dev.connect()
    assert fake.firmware_running and bytes(fake.uploaded) == FIRMWARE
    assert fake.boot_replies == 1
    assert any('loaded (attempt 1 of 1)' in m for m in dev.logs)
    dev.close()


class OtherBootloader(FakeFalcon):
    BOOT_REPLY = bytes((0x0A, 0x45, 0x2C, 0x0D))  # four bytes, but not the Falcon's answer


def test_bootloader_answer_is_checked_not_just_counted(tmp_path):
    fake = OtherBootloader(expected_firmware=FIRMWARE, boot_query_ignored=0)
    dev = make(fake, FIRMWARE, tmp_path, firmware_attempts=1, io_timeout=0.02,
               boot_query_tries=3)
    with pytest.raises(FalconError, match=r'0a 43 0d with 0a 44 2c 0d in 3 tries \(got 0a 45 2c 0d'):
        dev.connect()
    assert fake.uploaded == b'' and fake.boot_replies == 3  # asked again each time


def test_upload_chunks_are_62_bytes_and_normal_mode_purges(tmp_path):
    fake = FakeFalcon(expected_firmware=FIRMWARE)
    dev = make(fake, FIRMWARE, tmp_path, io_timeout=0.05)
    dev.connect()
    assert max(fake.upload_writes) == 62 and sum(fake.upload_writes) == len(FIRMWARE)
    # the bootloader's bytes from the speed change were purged, not fed to the packet parser
    assert dev.parser.dropped_bytes == 0 and dev.parser.malformed == 0
    last_servo_baud = max(i for i, c in enumerate(fake.calls) if c == ('baud', fp.NORMAL_BAUD))
    assert ('purge',) in fake.calls[last_servo_baud:]
    dev.close()


def test_missing_firmware_names_the_file_and_where_it_comes_from(tmp_path):
    dev = make(FakeFalcon(), io_timeout=0.02)
    with pytest.raises(FalconError, match=r'firmware_path.*nvent_firmware\.bin.*libnifalcon'):
        dev.connect()
    dev = FalconUSB(firmware_path=str(tmp_path / 'nope.bin'), guard_thread=False,
                    transport=PyFtdiTransport(ftdi_class(FakeFalcon())))
    with pytest.raises(FalconError, match=r"nope\.bin.*cannot read.*nvent_firmware\.bin"):
        dev.connect()


# -- 2. homing bit -----------------------------------------------------------------------------------
def test_homing_bit_stays_set_so_the_device_stays_homed():
    fake = FakeFalcon(firmware_running=True, homed=False, homes_after=3,
                      encoders=ticks_at(k.WORKSPACE_CENTER), powerup_offset=(40, -25, 10))
    dev = make(fake, homing=True)
    dev.connect()
    assert dev.homed
    for i in range(50):
        dev.write((1.0, 0.0, 0.0))
        dev.read(i * 1e-3)
    dev.check_stall(dev.clock() + 1.0)  # the guard's zero packet too
    dev.read(0.06)
    assert dev.homed and fake.homed and fake.homing_dropped == 0
    assert all(c.homing for c in fake.commands)
    dev.close()
    assert fake.commands[-1].homing  # and the last packet leaves it homed for the next session


# -- 3. kinematics constants -------------------------------------------------------------------------
def test_geometry_is_libnifalcons_corrected_2009_set():
    g = k.GEOMETRY
    assert (g.c, g.r, g.s) == (0.01443, 0.0400, -0.02309)
    old = dataclasses.replace(g, c=0.014, r=0.037233758, s=-0.027330909)
    p = k.WORKSPACE_CENTER
    q = k.forward_kinematics(k.inverse_kinematics(p, old), guess=p)
    assert math.dist(p, q) > 1e-3  # the old constants put the same arm angles > 1 mm away


# -- 4. unplug / I/O errors --------------------------------------------------------------------------
def test_unplug_mid_session_disconnects_zeroes_and_reconnects(tmp_path):
    clock = Clock(0.0)
    fake = FakeFalcon(expected_firmware=FIRMWARE, homed=False,
                      encoders=ticks_at(k.WORKSPACE_CENTER))
    events = []
    dev = make(fake, FIRMWARE, tmp_path, clock=clock, io_timeout=0.05, disconnect_after=20,
               reconnect=True, reconnect_period=0.5, max_force=10.0,
               on_disconnect=lambda m: events.append(('lost', m)),
               on_reconnect=lambda m: events.append(('back', m)))
    safety = SafetyLayer(max_force=10.0, max_force_rate=1e6, watchdog_timeout=1.0,
                         frame_id='tissue')
    loop = ServoLoop(dev, safety, rate=1000.0, clock=clock)
    dev.open(clock.t)
    safety.start(clock.t)

    def run(ticks, moving=True):
        s = None
        for _ in range(ticks):
            clock.t += 1e-3
            if moving:  # the user moves the grip: encoders change
                fake.encoders = ticks_at((0.0, 0.0, 0.11 + 0.01 * math.sin(10 * clock.t)))
            safety.command((3.0, 0.0, 0.0), clock.t, 'tissue')
            loop.tick(clock.t)
            s = dev.read(clock.t)
        return s

    s = run(100)
    assert dev.connected and math.dist(s.velocity, (0, 0, 0)) > 0.01
    assert math.dist(tip_force(dev, fake), (0, 0, 0)) == pytest.approx(3.0, abs=0.05)
    fake.unplug()
    s = run(30)
    assert dev.disconnected and not dev.connected and s.velocity == (0.0, 0.0, 0.0)
    assert [e[0] for e in events] == ['lost'] and 'unplugged' in events[0][1]
    assert loop.errors == 0  # nothing raised into the servo loop
    s = run(1000)            # unplugged for a second: reconnect attempts fail, logged
    assert dev.disconnected and s.velocity == (0.0, 0.0, 0.0)
    assert any('reconnect attempt 1 failed' in m for m in dev.logs)
    fake.replug(power_cycled=True)  # firmware and homing gone
    fake.homes_after = 50
    run(600, moving=False)
    assert [e[0] for e in events] == ['lost', 'back'] and dev.connected
    assert fake.firmware_running and dev.reconnects == 1
    assert 'not homed' in events[1][1]
    homing = [c for c in fake.commands[-600:] if c.leds == fp.LED_RED]
    assert homing and all(c.motors == (0, 0, 0) for c in homing)  # no force until homed
    assert dev.homed and fake.commands[-1].leds == fp.LED_GREEN
    assert math.dist(tip_force(dev, fake), (0, 0, 0)) == pytest.approx(3.0, abs=0.05)
    loop.stop()


def test_io_errors_on_write_count_towards_disconnect_and_guard_survives():
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    lost = []
    dev = make(fake, disconnect_after=5, reconnect=False, on_disconnect=lost.append)
    dev.connect()
    dev.write((1.0, 0.0, 0.0))
    fake.unplug()
    assert dev.check_stall(dev.clock() + 1.0)  # the guard's zero packet fails: no exception
    assert dev.io_errors == 1
    for i in range(5):
        dev.write((1.0, 0.0, 0.0))
    assert dev.disconnected and len(lost) == 1 and 'reconnect is off' in lost[0]
    dev.close()


# -- 5. motor commands scaled together ---------------------------------------------------------------
def test_saturated_motor_commands_keep_the_force_direction():
    p = (0.02, -0.02, 0.14)
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(p))
    dev = make(fake, max_force=60.0)  # a force the motors cannot give at this pose
    dev.connect()
    dev.read(0.0)
    dev.write((0.0, 0.0, 60.0))  # device z = Falcon y
    m = fake.commands[-1].motors
    assert max(abs(v) for v in m) == fp.INT16_MAX
    f = tip_force(dev, fake)
    cos = f[1] / math.dist(f, (0, 0, 0))
    assert cos > 0.9999 and dev.motor_scaled == 1  # shorter, same direction
    dev.close()


def test_motor_limit_is_configurable():
    p = (0.0, 0.0, 0.11)
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(p))
    dev = make(fake, max_motor_command=2000)
    dev.connect()
    dev.read(0.0)
    dev.write((3.0, 2.0, -4.0))
    assert max(abs(v) for v in fake.commands[-1].motors) == 2000
    f = falcon_usb.falcon_to_device(tip_force(dev, fake))
    n = math.dist(f, (0, 0, 0))
    assert sum(a * b for a, b in zip(f, (3.0, 2.0, -4.0))) / (n * math.sqrt(29)) > 0.9999
    with pytest.raises(ValueError, match='max_motor_command'):
        make(fake, max_motor_command=40000)


# -- 6. stall timeout and stall log ------------------------------------------------------------------
def test_each_stall_is_logged_and_the_default_timeout_is_above_the_jitter():
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = make(fake)
    # 50 ms, from bench/bench_falcon_jitter.py (README); the old 5 ms tripped ~30 times a second
    assert dev.stall_timeout == falcon_usb.DEFAULT_STALL_TIMEOUT > 0.005
    dev.connect()
    dev.write((1.0, 0.0, 0.0))
    assert not dev.check_stall(dev.clock() + 0.9 * dev.stall_timeout)
    assert dev.check_stall(dev.clock() + 2 * dev.stall_timeout)
    assert any('stalled' in m and 'sent zero force' in m for m in dev.logs)
    dev.close()


# -- 7. default force limit --------------------------------------------------------------------------
def test_default_force_limit_is_the_rated_force():
    assert falcon_usb.RATED_FORCE == pytest.approx(2 * 0.45359237 * 9.80665, abs=0.01)  # 2 lbf
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = make(fake)
    dev.connect()
    dev.read(0.0)
    dev.write((30.0, 0.0, 0.0))
    assert math.dist(tip_force(dev, fake), (0, 0, 0)) == pytest.approx(8.9, abs=0.02)
    dev.close()


# -- 8. homing false on a never-homed device ---------------------------------------------------------
def test_homing_false_on_a_never_homed_device_is_an_error():
    fake = FakeFalcon(firmware_running=True, homed=False, homes_after=10 ** 9,
                      powerup_offset=(100, 100, 100))  # nobody moves the grip
    dev = make(fake, homing=False)
    with pytest.raises(FalconError, match=r'homing is false but the Falcon is not homed'):
        dev.connect()
    assert not dev.connected and fake.closed and fake.commands[-1].motors == (0, 0, 0)


def test_guard_thread_outlives_a_usb_error():
    import time
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = FalconUSB(transport=PyFtdiTransport(ftdi_class(fake)), stall_timeout=0.01,
                    disconnect_after=10 ** 6, log=lambda m: None)  # real clock and guard thread
    dev.connect()
    dev.write((1.0, 0.0, 0.0))
    fake.unplug()
    deadline = time.monotonic() + 5.0
    while dev.stall_events == 0 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert dev.stall_events == 1 and dev.io_errors == 1
    assert dev._guard is not None and dev._guard.is_alive()  # still watching
    fake.replug(power_cycled=False)
    dev.write((1.0, 0.0, 0.0))  # the loop is back; a second stall is caught too
    deadline = time.monotonic() + 5.0
    while dev.stall_events < 2 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert dev.stall_events == 2
    dev.close()
