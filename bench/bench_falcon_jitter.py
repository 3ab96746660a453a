"""Servo-thread jitter: the gaps between consecutive packets the Falcon would receive.

The Falcon backend's stall guard sends zero force when no packet went out for ``stall_timeout``;
a timeout shorter than the servo loop's normal scheduling jitter gives spurious zero-force drops
(each followed by a 50 ms ramp back). This measures the tick-to-tick gaps of the driver's real
Falcon loop, each tick one packet: the compiled tick with the FalconUSB backend's I/O in a servo
process of its own (as ``falcon_driver`` runs it), against the fake Falcon of
test/support/falcon_fake.py (no hardware), the node sending a force command every millisecond.
The whole node graph's loop under load is ``bench/bench_servo_load.py``'s.

It prints p50 / p99 / p99.9 / max of the gaps [ms], how many exceed 5 / 10 / 25 / 50 / 100 ms, how
often the default stall_timeout would trip, and the load average. Printed, never asserted (shared
machine).

    .venv/bin/python bench/bench_falcon_jitter.py [--seconds 20]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test' / 'support'))  # the protocol-derived fake device

THRESHOLDS_MS = (5.0, 10.0, 25.0, 50.0, 100.0)


def usb_gaps(seconds: float) -> np.ndarray:
    from falcon_fake import FakeFalcon, ftdi_class

    from haptic_anfis.device import falcon_kinematics as k
    from haptic_anfis.device.falcon import WorkspaceMapping
    from haptic_anfis.device.falcon_usb import FalconError, FalconUSB, PyFtdiTransport
    from haptic_anfis.device.servo_native import NativeServoLoop
    from haptic_anfis.device.trace import TickTrace

    def device():  # built in the servo process, as the driver's factory is
        fake = FakeFalcon(firmware_running=True,
                          encoders=k.angles_to_ticks(k.inverse_kinematics(k.WORKSPACE_CENTER)))
        return FalconUSB(transport=PyFtdiTransport(ftdi_class(fake)), log=lambda m: None,
                         homing=False,
                         stall_timeout=10.0)  # the guard must not interfere with the measurement
    loop = NativeServoLoop(None, WorkspaceMapping(), mode='zoh', device_factory=device,
                           open_error=FalconError,
                           trace=TickTrace(max_rows=int(1000 * (seconds + 5))))
    loop.start()
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:  # a force command stream, as the force server sends
        loop.safety.command((1.0, 0.0, 0.0), time.monotonic(), 'tissue')
        time.sleep(0.001)
    loop.stop()
    t = loop.trace.arrays()[:, 0]  # each tick's time: one packet per tick
    return np.diff(t[len(t) // 20:])  # drop the start-up


def report(name: str, gaps: np.ndarray, timeout_ms: float) -> None:
    ms = gaps * 1e3
    p50, p99, p999 = np.percentile(ms, [50, 99, 99.9])
    over = ', '.join(f'>{t:g} ms: {int((ms > t).sum())}' for t in THRESHOLDS_MS)
    n = int((ms > timeout_ms).sum())
    print(f'{name:6s} n={len(ms)}  p50 {p50:.2f}  p99 {p99:.2f}  p99.9 {p999:.2f}  '
          f'max {ms.max():.2f} ms   ({over}); stall_timeout {timeout_ms:g} ms would trip '
          f'{n} times ({n / (gaps.sum() / 60):.1f} per minute)')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=20.0)
    a = ap.parse_args(argv)
    print(f'load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} on '
          f'{os.cpu_count()} cores; {a.seconds:g} s per setting')
    from haptic_anfis.device.falcon_usb import DEFAULT_STALL_TIMEOUT
    timeout_ms = DEFAULT_STALL_TIMEOUT * 1e3
    report('usb', usb_gaps(a.seconds), timeout_ms)
    print(f'load average after: {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
