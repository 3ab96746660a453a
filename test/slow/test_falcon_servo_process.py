"""The real Falcon's USB I/O and the compiled tick in a servo process of their own (issue 32):
the default for backend 'falcon'. The fake device lives in the servo process after the fork, so
what it receives is mirrored into shared memory (or a file, for a node in another process) that
the test reads. No hardware."""
from __future__ import annotations

import mmap
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from falcon_fake import ftdi_class

from haptic_anfis.device import falcon_kinematics as k
from haptic_anfis.device import falcon_usb

ROOT = Path(__file__).resolve().parents[2]
TEST_DIR = Path(__file__).resolve().parents[1] / 'support'  # falcon_fake
from falcon_fake import CLOSED, M0, N, PLUGGED, SharedFake, shared  # noqa: E402


def centred_fake(shm, **kw) -> SharedFake:
    return SharedFake(shm, firmware_running=True,
                      encoders=k.angles_to_ticks(k.inverse_kinematics(k.WORKSPACE_CENTER)), **kw)


def _wait(cond, seconds=10.0):
    deadline = time.monotonic() + seconds
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.005)
    return cond()


pytest.importorskip('rclpy')
from test_falcon_driver import driver  # noqa: E402  (the same node)

from haptic_anfis.nodes.parameters import ParameterError  # noqa: E402


def test_falcon_runs_in_a_servo_process_by_default_and_stops_at_zero(ctx, monkeypatch):
    shm = shared()
    fake = centred_fake(shm)
    monkeypatch.setattr(falcon_usb, 'import_ftdi', lambda: ftdi_class(fake))
    d = driver(ctx, backend='falcon', homing=False, gravity_compensation=True)
    try:
        assert d.servo_loop == 'native_process' and d.servo is not None
        assert d.servo._pid and d.servo._pid != os.getpid()
        assert 'servo process' in d.servo.scheduling
        assert _wait(lambda: d.device.replies >= 50 and shm[N] >= 50)
        assert d.device.connected and not d.device.disconnected
        # gravity compensation alone: a small non-zero command reaches the motors
        assert tuple(shm[M0:M0 + 3]) != (0.0, 0.0, 0.0)
        assert d.servo.errors == 0 and d.device.loop_errors == 0
        # the node publishes the servo process's ticks
        n = d.servo.stats.summary()['ticks'] if 'ticks' in d.servo.stats.summary() else None
        assert d.servo.last_state is not None, n
    finally:
        d.close()
        d.destroy_node()
    assert tuple(shm[M0:M0 + 3]) == (0.0, 0.0, 0.0) and shm[CLOSED] == 1.0
    assert d.device.state == 3  # STOPPED: the loop ended itself, not killed


def test_native_thread_is_refused_for_the_falcon_in_one_line(ctx):
    with pytest.raises(ParameterError, match=r"servo_loop: got 'native' with backend 'falcon'"):
        driver(ctx, backend='falcon', servo_loop='native')


def test_a_device_that_cannot_be_opened_is_one_line_at_start(ctx, monkeypatch):
    shm = shared()
    fake = SharedFake(shm, firmware_running=False)  # no firmware and no firmware file
    monkeypatch.setattr(falcon_usb, 'import_ftdi', lambda: ftdi_class(fake))
    with pytest.raises(falcon_usb.FalconError, match='runs no firmware.*firmware_path'):
        driver(ctx, backend='falcon')


def test_unplugged_falcon_in_the_servo_process_stops_the_node_with_exit_1(ctx, monkeypatch):
    shm = shared()
    fake = centred_fake(shm)
    monkeypatch.setattr(falcon_usb, 'import_ftdi', lambda: ftdi_class(fake))
    d = driver(ctx, backend='falcon', reconnect=False, disconnect_after=20)
    try:
        assert _wait(lambda: d.device.replies >= 50)
        shm[PLUGGED] = 0.0  # the cable, pulled in the servo process's fake
        assert _wait(lambda: d.finished)
        assert d.exit_code == 1 and d.device.disconnected and not d.safety.enabled
        assert d.servo.running and d.servo.errors == 0
    finally:
        d.close()
        d.destroy_node()


def test_replugged_falcon_in_the_servo_process_is_reconnected_and_force_resumes(ctx,
                                                                                 monkeypatch):
    """The cable pulled and put back (a loose cable: firmware and homing kept): the servo
    process reopens the device, the node's safety layer restarts, and force (gravity
    compensation) reaches the motors again."""
    shm = shared()
    fake = centred_fake(shm)
    monkeypatch.setattr(falcon_usb, 'import_ftdi', lambda: ftdi_class(fake))
    d = driver(ctx, backend='falcon', disconnect_after=20, reconnect_period=0.1,
               gravity_compensation=True, homing=False)
    try:
        assert _wait(lambda: d.device.replies >= 50)
        shm[PLUGGED] = 0.0
        assert _wait(lambda: d.device.disconnected and not d.safety.enabled)
        shm[PLUGGED] = 1.0
        assert _wait(lambda: d.device.reconnects == 1 and d.device.connected
                     and d.safety.enabled)
        assert not d.finished
        n = shm[N]
        assert _wait(lambda: shm[N] > n + 50 and tuple(shm[M0:M0 + 3]) != (0.0, 0.0, 0.0))
    finally:
        d.close()
        d.destroy_node()


NODE = textwrap.dedent('''
    import mmap, sys, time
    import numpy as np
    sys.path.insert(0, {test_dir!r})
    from falcon_fake import SharedFake, ftdi_class
    from haptic_anfis.device import falcon_kinematics as k, falcon_usb
    from haptic_anfis.device.falcon import WorkspaceMapping
    from haptic_anfis.device.servo_native import NativeServoLoop

    f = open({path!r}, 'r+b')
    shm = np.frombuffer(mmap.mmap(f.fileno(), 64), dtype=np.float64)
    fake = SharedFake(shm, firmware_running=True,
                      encoders=k.angles_to_ticks(k.inverse_kinematics(k.WORKSPACE_CENTER)))
    factory = lambda: falcon_usb.FalconUSB(homing=False, transport=falcon_usb.PyFtdiTransport(
        ftdi_class(fake)))
    loop = NativeServoLoop(None, WorkspaceMapping(), mode='zoh', watchdog_timeout=0.010,
                           device_factory=factory, open_error=falcon_usb.FalconError)
    loop.start()
    print('pid', loop._pid, flush=True)
    while True:  # the node: a force command every 2 ms, until it is frozen
        loop.safety.command((0.0, 0.0, 3.0), time.monotonic(), 'tissue')
        time.sleep(0.002)
''')


def test_a_frozen_node_cannot_leave_force_on_the_motors(tmp_path):
    """The node process is SIGSTOPped while it commands 3 N: the servo process keeps ticking on
    its own, its watchdog zeroes the motors within the watchdog time (10 ms) plus the force ramp,
    and it keeps sending zero; SIGCONT brings the commanded force back."""
    path = tmp_path / 'shm'
    path.write_bytes(bytes(64))
    script = NODE.format(test_dir=str(TEST_DIR), path=str(path))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(TEST_DIR)]))
    node = subprocess.Popen([sys.executable, '-c', script], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    f = open(path, 'r+b')
    shm = np.frombuffer(mmap.mmap(f.fileno(), 64), dtype=np.float64)
    try:
        line = node.stdout.readline()
        assert line.startswith('pid'), node.stderr.read() if node.poll() is not None else line
        servo_pid = int(line.split()[1])
        assert _wait(lambda: shm[N] > 200 and tuple(shm[M0:M0 + 3]) != (0.0, 0.0, 0.0))
        os.kill(node.pid, signal.SIGSTOP)
        t_stop = time.monotonic()
        assert _wait(lambda: tuple(shm[M0:M0 + 3]) == (0.0, 0.0, 0.0), 2.0)
        zeroed_after = time.monotonic() - t_stop
        print(f"zeroed {zeroed_after * 1e3:.1f} ms after SIGSTOP")
        n = shm[N]
        time.sleep(0.2)
        assert shm[N] > n + 50  # the servo process keeps sending (zero) while the node is frozen
        assert tuple(shm[M0:M0 + 3]) == (0.0, 0.0, 0.0)
        # polled every 5 ms by a test process that shares 2 cores with both: a loose bound
        assert zeroed_after < 0.5, zeroed_after
        os.kill(node.pid, signal.SIGCONT)
        assert _wait(lambda: tuple(shm[M0:M0 + 3]) != (0.0, 0.0, 0.0), 5.0)
    finally:
        os.kill(node.pid, signal.SIGCONT)
        node.terminate()  # the servo process gets SIGTERM with its parent: zero, closed
        node.wait(10)
        f.close()
    # the servo process got SIGTERM with its parent: it stopped its loop, sent zero, closed
    assert _wait(lambda: shm[CLOSED] == 1.0, 5.0), servo_pid
    assert tuple(shm[M0:M0 + 3]) == (0.0, 0.0, 0.0)


class _Finalised:
    """Garbage with a finalizer that writes the pid of the process that collects it."""

    def __init__(self, shm):
        self.shm, self.me = shm, self

    def __del__(self):
        self.shm[7] = os.getpid()


def test_the_servo_process_never_collects_the_parents_garbage(ctx, monkeypatch):
    """Garbage the driver's process holds at the fork (here: a cycle with a finalizer, as an
    rclpy node left undestroyed makes) is never collected in the servo process: its finalizer
    would call into DDS, whose locks the parent's threads may have held at the fork (the
    device loop hung). The device factory runs in the servo process: it collects there first."""
    import gc
    shm = shared()
    fake = centred_fake(shm)

    def factory_collecting():
        gc.collect()
        return falcon_usb.FalconUSB(homing=False, transport=falcon_usb.PyFtdiTransport(
            ftdi_class(fake)))

    monkeypatch.setattr(falcon_usb, 'import_ftdi', lambda: ftdi_class(fake))
    from haptic_anfis.device import driver_loops
    monkeypatch.setattr(driver_loops, 'falcon_factory', lambda p: lambda **kw: factory_collecting())
    gc.disable()
    try:
        _Finalised(shm)  # unreachable at once: garbage
        d = driver(ctx, backend='falcon', homing=False)
        try:
            assert _wait(lambda: d.device.replies >= 50)
            assert shm[7] == 0.0, f'collected in process {shm[7]:.0f} (this one: {os.getpid()})'
        finally:
            d.close()
            d.destroy_node()
    finally:
        gc.enable()
    gc.collect()
    assert shm[7] == os.getpid()  # collected here, where it belongs


def test_threshold_presses_on_a_falcon_render_the_spring_in_its_servo_process():
    """The threshold's spring on a (fake) Falcon held 15 mm (tissue) into the plane: one servo
    process for the series; each press measures the asked stiffness from the ticks it got, and
    between presses and after the series the motors are at zero."""
    from haptic_anfis.device.falcon import WorkspaceMapping
    from haptic_anfis.device.stiffness_press import DevicePresses
    shm = shared()
    # device x -0.01 m (15 mm into the plane through the workspace's centre, tissue frame)
    grip = tuple(c + o for c, o in zip(k.WORKSPACE_CENTER,
                                       falcon_usb.device_to_falcon((-0.01, 0.0, 0.0))))
    fake = SharedFake(shm, firmware_running=True,
                      encoders=k.angles_to_ticks(k.inverse_kinematics(grip)))
    factory = lambda: falcon_usb.FalconUSB(  # noqa: E731
        homing=False, transport=falcon_usb.PyFtdiTransport(ftdi_class(fake)))
    mapping = WorkspaceMapping()
    between = []
    with DevicePresses(factory, mapping.offset[0], 0.3, mapping,
                       before=lambda: between.append(tuple(shm[M0:M0 + 3]))) as presses:
        pid = presses.loop._pid
        assert pid and pid != os.getpid()
        got = [presses(stiffness) for stiffness in (200.0, 300.0)]
        time.sleep(0.1)
        between.append(tuple(shm[M0:M0 + 3]))
    for stiffness, p in zip((200.0, 300.0), got):
        assert p.peak_depth == pytest.approx(0.015, abs=1e-3)
        assert p.stiffness == pytest.approx(stiffness, rel=0.05), got
    assert between[0] == between[-1] == (0.0, 0.0, 0.0), between
    assert _wait(lambda: shm[CLOSED] == 1.0, 5.0)
