"""The Falcon USB backend (haptic_anfis.device.falcon_usb) against a fake FTDI device: no hardware,
no USB library. Firmware upload and its retries, homing, the byte stream, forces, the stall
guard, the servo loop with the safety layer."""
from __future__ import annotations

import atexit
import math
import sys
import time

import numpy as np
import pytest
from falcon_fake import Clock, FakeFalcon, Received, ftdi_class

from haptic_anfis.device import falcon_kinematics as k
from haptic_anfis.device import falcon_protocol as fp
from haptic_anfis.device.falcon_usb import (FalconError, FalconUnavailableError, FalconUSB,
                                            PyFtdiTransport, device_to_falcon, falcon_to_device,
                                            import_ftdi)
from tick_oracle import SafetyLayer, ServoLoop

FIRMWARE = bytes(range(256)) * 3 + b'tail'  # 772 bytes: 6 full chunks and a short one


def make(device: FakeFalcon, firmware: bytes | None = None, tmp_path=None, clock=None, **kw):
    logs = []
    path = ''
    if firmware is not None:
        path = str(tmp_path / 'falcon_fw.bin')
        (tmp_path / 'falcon_fw.bin').write_bytes(firmware)
    clock = clock or Clock()
    dev = FalconUSB(firmware_path=path, transport=PyFtdiTransport(ftdi_class(device)),
                    clock=clock, sleep=clock.sleep, log=logs.append,
                    guard_thread=kw.pop('guard_thread', False), **kw)
    dev.logs = logs
    return dev


def ticks_at(p):
    return k.angles_to_ticks(k.inverse_kinematics(p))


def last_motors(device):
    return device.commands[-1].motors


# -- connecting ------------------------------------------------------------------------------------
def test_running_firmware_is_used_and_motors_start_at_zero():
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at((0.01, -0.02, 0.12)), buttons=0b0101)
    dev = make(fake)
    dev.open(0.0)
    assert dev.connected and dev.homed
    assert any('already running' in m for m in dev.logs)
    assert fake.baud == fp.NORMAL_BAUD and fake.latency == fp.NORMAL_LATENCY_MS
    assert fake.uploaded == b''
    assert all(c.motors == (0, 0, 0) for c in fake.commands)
    s = dev.read(0.001)
    # device frame: x = Falcon z - centre, y = Falcon x, z = Falcon y; tick quantisation ~0.1 mm
    assert np.allclose(s.position, (0.12 - k.WORKSPACE_CENTER[2], 0.01, -0.02), atol=2e-4)
    assert s.buttons == (1, 0, 1, 0)
    dev.close()
    assert fake.closed and fake.commands[-1] == Received((0, 0, 0), 0, True)  # LEDs off, homed


def test_firmware_upload_retries_then_succeeds(tmp_path):
    fake = FakeFalcon(expected_firmware=FIRMWARE, corrupt_echo_at=100)
    dev = make(fake, FIRMWARE, tmp_path, firmware_attempts=3, io_timeout=0.05)
    logs = dev.logs
    dev.log = lambda m: (logs.append(m), setattr(fake, 'corrupt_echo_at', None))  # 1 bad line
    dev.connect()
    assert fake.firmware_running and bytes(fake.uploaded) == FIRMWARE
    assert any('attempt 1 of 3 failed' in m and 'echo mismatch at byte 100' in m
               for m in dev.logs)
    assert any('loaded (attempt 2 of 3)' in m for m in dev.logs)
    assert ('line', 8, 1, 'N') in fake.calls and ('flow', '') in fake.calls
    assert fake.baud == fp.NORMAL_BAUD
    dev.close()


def test_firmware_upload_failure_says_why_every_attempt_failed(tmp_path):
    fake = FakeFalcon(expected_firmware=FIRMWARE, boot_query_ignored=10 ** 6)
    dev = make(fake, FIRMWARE, tmp_path, firmware_attempts=3, io_timeout=0.02,
               boot_query_tries=4)
    with pytest.raises(FalconError) as exc:
        dev.connect()
    msg = str(exc.value)
    assert 'in 3 attempt(s)' in msg and 'falcon_fw.bin' in msg
    for i in (1, 2, 3):
        assert (f'attempt {i}: the bootloader did not answer its query 0a 43 0d with '
                '0a 44 2c 0d in 4 tries (no bytes)') in msg
    assert 'power supply' in msg and 'firmware_attempts' in msg
    assert not dev.connected and fake.closed  # cleaned up, nothing left open


def test_firmware_echo_mismatch_is_reported_with_the_byte(tmp_path):
    fake = FakeFalcon(expected_firmware=FIRMWARE, corrupt_echo_at=300)
    dev = make(fake, FIRMWARE, tmp_path, firmware_attempts=2, io_timeout=0.02)
    with pytest.raises(FalconError, match='attempt 2: echo mismatch at byte 300 of 772'):
        dev.connect()


def test_no_firmware_and_no_path_asks_for_firmware_path():
    dev = make(FakeFalcon(firmware_running=False), io_timeout=0.02)
    with pytest.raises(FalconError, match='firmware_path'):
        dev.connect()


def test_missing_firmware_file_fails_before_touching_usb(tmp_path):
    fake = FakeFalcon()
    dev = FalconUSB(firmware_path=str(tmp_path / 'nope.bin'),
                    transport=PyFtdiTransport(ftdi_class(fake)), guard_thread=False)
    with pytest.raises(FalconError, match="firmware_path .*nope.bin.*cannot read"):
        dev.connect()
    assert fake.open_args is None


def test_absent_device_message_lists_what_was_found():
    gone = FakeFalcon()
    gone.unplug()
    dev = make(gone)
    with pytest.raises(FalconError,
                       match=r'cannot open the Novint Falcon \(index 0.*found: 0.*udev'):
        dev.connect()
    dev = make(FakeFalcon(), serial='OTHER')
    with pytest.raises(FalconError, match=r"serial 'OTHER'.*FAKE0001"):
        dev.connect()


def test_missing_usb_library_tells_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, 'pyftdi', None)
    monkeypatch.setitem(sys.modules, 'pyftdi.ftdi', None)
    with pytest.raises(FalconUnavailableError, match=r"pip install 'haptic_anfis\[falcon\]'"):
        import_ftdi()
    dev = FalconUSB(guard_thread=False)  # constructing needs no USB library...
    with pytest.raises(FalconUnavailableError, match='pyftdi'):
        dev.connect()                     # ...connecting does
    assert isinstance(FalconUnavailableError('x'), OSError)  # run_node: one-line error, exit 1


def test_homing_waits_for_the_arms_with_red_led():
    fake = FakeFalcon(firmware_running=True, homed=False, homes_after=5)
    dev = make(fake, homing=True)
    dev.connect()
    assert dev.homed
    assert all(c.homing for c in fake.commands)  # the homing bit is in every packet
    red = [c for c in fake.commands if c.leds == fp.LED_RED]
    assert len(red) >= 5 and fake.commands[0].leds == fp.LED_GREEN  # the probe, then homing
    assert fake.commands[-1] == Received((0, 0, 0), fp.LED_GREEN, True)
    assert any('push it straight all the way in' in m for m in dev.logs)
    dev.close()


def test_homing_timeout_fails_clearly():
    fake = FakeFalcon(firmware_running=True, homed=False, homes_after=10 ** 9)
    dev = make(fake, homing=True, homing_timeout=0.05)
    with pytest.raises(FalconError, match=r'homing timed out after 0.05 s \(homed flags 0b000'):
        dev.connect()
    assert fake.commands[-1].motors == (0, 0, 0) and fake.closed


# -- the byte stream -------------------------------------------------------------------------------
def test_positions_from_a_synthetic_stream_cut_anywhere_with_garbage():
    fake = FakeFalcon(firmware_running=True, max_read=5, garbage=b'\x00x')
    dev = make(fake)
    dev.connect()
    c = np.array(k.WORKSPACE_CENTER)
    path = [c + 0.03 * np.array((math.sin(t), math.cos(2 * t), 0.5 * math.sin(3 * t)))
            for t in np.linspace(0, 2 * math.pi, 60)]
    errs, got = [], 0
    for i, p in enumerate(path):
        fake.encoders = ticks_at(p)
        dev.write((0.0, 0.0, 0.0))
        for _ in range(8):  # 5 bytes per USB read: a reply takes several reads
            s = dev.read(i * 1e-3)
        got += 1
        errs.append(np.max(np.abs(np.array(device_to_falcon(s.position)) + c - p)))
    assert max(errs) < 2e-4  # one encoder tick moves the tip ~0.04-0.1 mm
    assert dev.parser.packets >= len(path) and dev.kinematics_errors == 0
    dev.close()


# Two reply packets written out by hand from the packet layout (falcon_protocol's docstring, which
# follows libnifalcon's FalconFirmwareNovintSDK): '<', encoders 1-3 as four 'A'+nibble bytes each,
# least significant first, byte 13 = 'A' + (buttons | homed << 4), byte 14 = 'A', '>'. They do not
# come from encode_reply, so the decoder is checked against an independent byte stream.
#   -516 = 0xFDFC -> C F D F -> 'MPNP'; buttons 0, homed 0b111 -> 0x70 -> 0xB1
#   28 = 0x001C -> 'MBAA'; -616 = 0xFD98 -> 'IJNP'; -484 = 0xFE1C -> 'MBOP'; buttons 0b0101 -> 0xB6
HAND_PACKETS = (b'\x00junk<MPNPMPNPMPNP\xb1A>', b'><MBAAIJNPMBOP\xb6A>')  # with stray bytes


def test_backend_driven_by_a_hand_written_byte_stream():
    fake = FakeFalcon(firmware_running=True, max_read=7)
    dev = make(fake)
    dev.connect()
    fake.replying = False  # the device side is now the fixed stream below
    while fake.rx:  # take the replies to connect()'s packets first
        dev.read(0.0)
    c = np.array(k.WORKSPACE_CENTER)
    # ticks (-516, -516, -516) are the workspace centre; (28, -616, -484) are 10 / -20 / 5 mm off
    # (with libnifalcon's 2009 geometry constants)
    expected = [((0, 0, 0, 0), c), ((1, 0, 1, 0), c + (0.01, -0.02, 0.005))]
    for chunk, (buttons, where) in zip(HAND_PACKETS, expected):
        before = dev.parser.packets
        fake.rx += chunk
        for i in range(10):  # 7 bytes per USB read: a packet takes several reads
            state = dev.read(i * 1e-3)
            if dev.parser.packets > before:
                break
        assert dev.parser.packets == before + 1
        assert state.buttons == buttons
        assert np.allclose(np.array(device_to_falcon(state.position)) + c, where, atol=2e-4)
    assert dev.kinematics_errors == 0
    dev.close()


def test_velocity_is_filtered_finite_difference():
    clock = Clock()
    fake = FakeFalcon(firmware_running=True)
    dev = make(fake, clock=clock, velocity_cutoff=1e6)  # no filtering to speak of
    dev.connect()
    c = np.array(k.WORKSPACE_CENTER)
    for i in range(5):
        fake.encoders = ticks_at(c + (0.0, 0.0, 1.0 * i * 1e-3))  # +z_F at 1 m/s
        dev.write((0, 0, 0))
        clock.t += 1e-3
        s = dev.read(clock.t)
    assert s.velocity[0] == pytest.approx(1.0, rel=0.1)  # device x = Falcon z (tick-quantised)
    assert abs(s.velocity[1]) < 0.1 and abs(s.velocity[2]) < 0.1
    dev.close()


def test_garbage_and_missing_replies_are_counted_not_fatal():
    fake = FakeFalcon(firmware_running=True)
    dev = make(fake)
    dev.connect()
    s0 = dev.read(0.0)  # the reply to connect's last packet
    fake.replying = False
    dev.write((0, 0, 0))
    assert dev.read(0.001) == s0
    fake.rx += b'<AAA>' + b'\xff' * 10
    s1 = dev.read(0.002)
    assert dev.missed_replies == 2 and dev.parser.malformed >= 1 and s1.position == s0.position


# -- forces ----------------------------------------------------------------------------------------
@pytest.mark.parametrize('force', [(3.0, 0.0, 0.0), (0.0, -2.0, 1.0), (1.5, 2.5, -4.0)])
def test_force_reaches_the_motors_as_jacobian_transpose_torques(force):
    p = (0.012, -0.008, 0.115)
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(p))
    dev = make(fake)
    dev.connect()
    dev.read(0.0)
    dev.write(force)
    tau = k.commands_to_torques(last_motors(fake))
    f_tip = k.torque_to_force(dev._p, tau)
    # one command count is 1e-4 N m: ~2 mN at the tip
    assert np.allclose(falcon_to_device(f_tip), force, atol=0.01)
    dev.close()


def test_clamp_and_gravity_compensation():
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = make(fake, max_force=10.0, gravity_compensation=True, gravity_mass=0.2)
    dev.connect()
    dev.read(0.0)
    assert dev.tip_force((0, 0, 0)) == pytest.approx((0.0, 0.2 * k.G, 0.0))  # Falcon +y: up
    dev.write((0, 0, 0))
    f = k.torque_to_force(dev._p, k.commands_to_torques(last_motors(fake)))
    assert f[1] == pytest.approx(0.2 * k.G, abs=0.01)
    assert math.dist(dev.tip_force((30.0, 40.0, 0.0)), (0, 0, 0)) == pytest.approx(10.0)
    assert dev.tip_force((math.nan, 1.0, 0.0)) == pytest.approx((0.0, 0.2 * k.G, 0.0))
    dev.gravity_compensation = False
    assert dev.tip_force((math.inf, 0, 0)) == (0.0, 0.0, 0.0)
    dev.write((0.0, 0.0, 0.0))
    assert last_motors(fake) == (0, 0, 0)
    dev.close()


# -- the stall guard -------------------------------------------------------------------------------
def test_stall_guard_sends_zero_then_ramps_back():
    clock = Clock()
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = make(fake, clock=clock, stall_timeout=0.005, resume_ramp=0.05, max_force=10.0)
    dev.connect()
    dev.read(clock.t)
    dev.write((5.0, 0.0, 0.0))
    assert last_motors(fake) != (0, 0, 0)
    clock.t += 0.004
    assert not dev.check_stall()
    clock.t += 0.002                       # 6 ms without a packet: the loop stalled
    assert dev.check_stall()
    assert last_motors(fake) == (0, 0, 0)  # the last thing the device got is zero force
    n = len(fake.commands)
    assert not dev.check_stall(clock.t + 1.0) and len(fake.commands) == n  # once per stall
    dev.write((5.0, 0.0, 0.0))             # the loop is back: force ramps up from zero
    f0 = k.torque_to_force(dev._p, k.commands_to_torques(last_motors(fake)))
    assert math.dist(f0, (0, 0, 0)) < 0.05
    clock.t += 0.025
    dev.write((5.0, 0.0, 0.0))
    f1 = k.torque_to_force(dev._p, k.commands_to_torques(last_motors(fake)))
    assert math.dist(f1, (0, 0, 0)) == pytest.approx(5.0, abs=0.05)  # half way: 5 of 10 N
    clock.t += 0.03
    dev.write((5.0, 0.0, 0.0))
    f2 = k.torque_to_force(dev._p, k.commands_to_torques(last_motors(fake)))
    assert math.dist(f2, (0, 0, 0)) == pytest.approx(5.0, abs=0.01)
    assert dev.stall_events == 1
    dev.close()


def test_stall_guard_thread_zeroes_a_stalled_loop_and_close_zeroes():
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = FalconUSB(transport=PyFtdiTransport(ftdi_class(fake)), stall_timeout=0.005,
                    log=lambda m: None)  # real clock, real guard thread
    dev.connect()
    dev.read(time.monotonic())
    dev.write((4.0, 0.0, 0.0))
    assert last_motors(fake) != (0, 0, 0)
    deadline = time.monotonic() + 2.0
    while dev.stall_events == 0 and time.monotonic() < deadline:
        time.sleep(0.002)
    assert dev.stall_events >= 1 and last_motors(fake) == (0, 0, 0)
    dev.write((4.0, 0.0, 0.0))
    dev.close()
    assert fake.commands[-1].motors == (0, 0, 0) and fake.closed
    assert dev._guard is None
    dev.close()  # twice is fine


def test_atexit_hook_zeroes_an_open_device(monkeypatch):
    hooks = []
    monkeypatch.setattr(atexit, 'register', hooks.append)
    monkeypatch.setattr(atexit, 'unregister', lambda f: hooks.remove(f) if f in hooks else None)
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = make(fake)
    dev.connect()
    dev.read(0.0)
    dev.write((3.0, 0.0, 0.0))
    assert len(hooks) == 1
    hooks[0]()  # what the interpreter runs at exit
    assert fake.commands[-1].motors == (0, 0, 0) and fake.closed and not hooks


# -- with the servo loop and the safety layer ------------------------------------------------------
def test_servo_loop_with_safety_layer_drives_the_falcon_and_stops_at_zero():
    clock = Clock(0.0)
    fake = FakeFalcon(firmware_running=True, encoders=ticks_at(k.WORKSPACE_CENTER))
    dev = make(fake, clock=clock, max_force=10.0)
    safety = SafetyLayer(max_force=10.0, max_force_rate=1000.0, watchdog_timeout=0.010,
                         frame_id='tissue')
    loop = ServoLoop(dev, safety, rate=1000.0, clock=clock)
    dev.open(clock.t)
    safety.start(clock.t)
    forces = []
    for i in range(40):
        clock.t = i * 1e-3
        if i < 20:
            safety.command((30.0, 0.0, 0.0), clock.t, 'tissue')  # clamped to 10 N
        loop.tick(clock.t)
        forces.append(math.dist(
            k.torque_to_force(dev._p, k.commands_to_torques(last_motors(fake))), (0, 0, 0)))
    assert max(forces) == pytest.approx(10.0, abs=0.05)         # clamp
    assert forces[3] == pytest.approx(3.0, abs=0.05)             # rate limit: 1 N per ms
    assert forces[-1] < 1e-9                                     # watchdog ramped to zero
    loop.stop()                                                  # no thread: stop zeroes, closes
    assert fake.commands[-1].motors == (0, 0, 0) and fake.closed
