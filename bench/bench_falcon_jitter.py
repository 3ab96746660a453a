"""Servo-thread jitter: the gaps between consecutive packets the Falcon would receive.

The Falcon backend's stall guard sends zero force when no packet went out for ``stall_timeout``;
a timeout shorter than the servo thread's normal scheduling jitter gives spurious zero-force drops
(each followed by a 50 ms ramp back). This measures the write-to-write gaps of the 1 kHz servo
thread in two settings:

  1. ``usb``: the FalconUSB backend against the fake Falcon of test/support/falcon_fake.py (no hardware),
     ServoLoop + SafetyLayer, nothing else in the process;
  2. ``graph``: the whole one-process node graph (driver, contact detector, force server, ROS
     executor) with the simulated device, each device write time-stamped.

It prints p50 / p99 / p99.9 / max of the gaps [ms], how many exceed 5 / 10 / 25 / 50 / 100 ms, how
often the default stall_timeout would trip, and the load average. Printed, never asserted (shared
machine).

    .venv/bin/python bench/bench_falcon_jitter.py [--seconds 20] [--only usb|graph]
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

    from haptic_anfis.device import SafetyLayer, ServoLoop
    from haptic_anfis.device import falcon_kinematics as k
    from haptic_anfis.device.falcon_usb import FalconUSB, PyFtdiTransport
    fake = FakeFalcon(firmware_running=True,
                      encoders=k.angles_to_ticks(k.inverse_kinematics(k.WORKSPACE_CENTER)))
    dev = FalconUSB(transport=PyFtdiTransport(ftdi_class(fake)), log=lambda m: None,
                    stall_timeout=10.0)  # the guard must not interfere with the measurement
    safety = SafetyLayer(frame_id='tissue')
    loop = ServoLoop(dev, safety, rate=1000.0)
    loop.start()
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:  # a force command stream, as the force server sends
        safety.command((1.0, 0.0, 0.0), time.monotonic(), 'tissue')
        time.sleep(0.001)
    loop.stop()
    t = np.array(fake.write_times)
    return np.diff(t[len(t) // 20:])  # drop the start-up


def graph_gaps(seconds: float) -> np.ndarray:
    from haptic_anfis.session import open_graph
    g = open_graph(program='bench_jitter')
    stamps: list[float] = []
    dev = g.driver.device
    write = dev.write

    def stamped(force):
        stamps.append(time.monotonic())
        write(force)
    dev.write = stamped
    try:
        g.spin_for(30.0, lambda: g.driver.first_command is not None)
        stamps.clear()
        g.spin_for(seconds)
    finally:
        g.shutdown()
    return np.diff(np.array(stamps))


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
    ap.add_argument('--only', choices=('usb', 'graph'))
    a = ap.parse_args(argv)
    print(f'load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} on '
          f'{os.cpu_count()} cores; {a.seconds:g} s per setting')
    from haptic_anfis.device.falcon_usb import DEFAULT_STALL_TIMEOUT
    timeout_ms = DEFAULT_STALL_TIMEOUT * 1e3
    if a.only in (None, 'usb'):
        report('usb', usb_gaps(a.seconds), timeout_ms)
    if a.only in (None, 'graph'):
        report('graph', graph_gaps(a.seconds), timeout_ms)
    print(f'load average after: {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
