"""A step-by-step hardware check of a Novint Falcon, and the force-scale calibration (no ROS).

:func:`run_check` finds the device, loads firmware, homes (LED red until homed, then green, as
libnifalcon's findfalcons does), reads positions while the user moves the grip, renders a gentle
spring (at most ``spring_force`` N, towards the workspace centre) for a few seconds, then zero force
and close. Each step prints what it saw; the first failing step stops the check and its number is
the result, so a user can report exactly where it fails.

:func:`calibrate` measures the motor-command scale (``counts_per_nm``, counts per N m): the grip is
held by a virtual spring at its rest position; hanging a known mass on it makes the spring stretch
until the COMMANDED extra upward force balances the weight. If the scale were right that extra
force would be ``m g``; the ratio gives the scale the motors really have::

    counts_per_nm_true = counts_per_nm_used * dF_commanded / (m g)

(commanded counts = c_used * tau_cmd, real torque = counts / c_true, balance: real force = m g).
The reference's -10000 counts per N m was tuned with its approximate Jacobian; ours is exact, so
the same constant renders 7-35 % softer: calibrate before trusting force magnitudes.
"""
from __future__ import annotations

import atexit
import dataclasses
import math
import re
import time
from pathlib import Path
from typing import Callable

from .falcon_kinematics import GEOMETRY, G
from .falcon_usb import FalconError, FalconUSB, PyFtdiTransport
from ..errors import HapticAnfisError

Say = Callable[[str], None]


class CheckFailed(HapticAnfisError):
    """A check step failed; ``step`` is its number (1-based), the message says why."""

    def __init__(self, step: int, message: str):
        super().__init__(f'step {step} failed: {message}')
        self.step = step


def _servo(dev: FalconUSB, seconds: float, force_of: Callable[[tuple], tuple],
           rate: float = 1000.0, clock=time.monotonic, sleep=time.sleep,
           every: Callable[[float, object], None] | None = None) -> dict:
    """Run a plain servo loop for ``seconds``: read, force = ``force_of(position)``, write.
    Returns what it saw: replies, positions range [m], buttons ever pressed, largest force [N]."""
    t0 = clock()
    lo, hi = [math.inf] * 3, [-math.inf] * 3
    buttons, fmax, replies0 = [0, 0, 0, 0], 0.0, dev.replies
    period = 1.0 / rate
    deadline = t0
    while True:
        now = clock()
        if now - t0 >= seconds:
            break
        s = dev.read(now)
        for i in range(3):
            lo[i], hi[i] = min(lo[i], s.position[i]), max(hi[i], s.position[i])
        for i, b in enumerate(s.buttons):
            buttons[i] |= b
        f = force_of(s.position)
        fmax = max(fmax, math.sqrt(sum(v * v for v in f)))
        dev.write(f)
        if every is not None:
            every(now - t0, s)
        deadline += period
        delay = deadline - clock()
        if delay > 0:
            sleep(delay)
    dev.write((0.0, 0.0, 0.0))
    return {'replies': dev.replies - replies0, 'low': tuple(lo), 'high': tuple(hi),
            'buttons': tuple(buttons), 'max_force': fmax}


def spring_to_centre(stiffness: float, limit: float) -> Callable[[tuple], tuple]:
    """F = -stiffness * p, at most ``limit`` N (device frame, origin = workspace centre)."""
    def force(p):
        f = tuple(-stiffness * v for v in p)
        n = math.sqrt(sum(v * v for v in f))
        return f if n <= limit else tuple(v * limit / n for v in f)
    return force


def run_check(dev: FalconUSB, say: Say = print, move_seconds: float = 5.0,
              spring_seconds: float = 5.0, spring_force: float = 1.0, clock=time.monotonic,
              sleep=time.sleep, keep_open: bool = False) -> int:
    """The check (see the module doc). Returns 0 when every step passed, else the number of the
    failed step (after printing why). The device is closed at the end (at zero force), unless all
    passed and ``keep_open`` (for the calibration that follows)."""
    step = 0
    try:
        step = 1
        say('1. find: looking for a Falcon on USB (0403:cb48) ...')
        if dev.transport is None:
            dev.transport = PyFtdiTransport()
        found = dev.transport.list_devices()
        if not found:
            raise CheckFailed(1, 'no Falcon found on USB: check the cable, the power supply and '
                                 'the udev rule for 0403:cb48')
        say(f'   [ok] {len(found)} found (serials {", ".join(found)})')
        step = 2
        say('2. firmware: opening, loading firmware if it runs none ...')
        try:
            dev.transport.open(dev.device_index, dev.serial)
            dev._connected = True
            atexit.register(dev.close)  # zero force however the check ends
            dev._bring_up(dev._read_firmware_file())
        except (OSError, ValueError) as exc:
            raise CheckFailed(2, str(exc)) from None
        say(f'   [ok] firmware answers servo packets ({dev.replies} replies so far)')
        step = 3
        say('3. homing: LED red; move the grip all the way out, then push it straight all the way '
            'in (LED turns green when homed)')
        try:
            dev._home()
            dev._send_zero(dev.leds)
            dev._start_guard()
        except FalconError as exc:
            raise CheckFailed(3, str(exc)) from None
        say('   [ok] homed, LED green')
        step = 4
        say(f'4. positions: move the grip around for {move_seconds:g} s (no force) ...')
        shown = [0.0]

        def show(t, s):
            if t >= shown[0]:
                shown[0] += 0.5
                say('   t {:4.1f} s  position ({:+7.1f}, {:+7.1f}, {:+7.1f}) mm  buttons {}'.format(
                    t, *(1e3 * v for v in s.position), ''.join(map(str, s.buttons))))
        seen = _servo(dev, move_seconds, lambda p: (0.0, 0.0, 0.0), clock=clock, sleep=sleep,
                      every=show)
        span = [1e3 * (h - lo) for lo, h in zip(seen['low'], seen['high'])]
        say(f"   saw {seen['replies']} replies; range x {span[0]:.1f}, y {span[1]:.1f}, "
            f"z {span[2]:.1f} mm; buttons pressed {''.join(map(str, seen['buttons']))}")
        if seen['replies'] == 0:
            raise CheckFailed(4, 'no replies while reading positions (cable? power?)')
        if max(span) < 1.0:
            raise CheckFailed(4, 'the position did not change by 1 mm: encoders or kinematics '
                                 'wrong, or the grip was not moved')
        say('   [ok]')
        step = 5
        k = spring_force / 0.02  # the full force 2 cm from the centre
        say(f'5. spring: {spring_force:g} N at most towards the centre for {spring_seconds:g} s; '
            'hold the grip lightly and feel it pull to the middle ...')
        seen = _servo(dev, spring_seconds, spring_to_centre(k, spring_force), clock=clock,
                      sleep=sleep)
        say(f"   largest force sent {seen['max_force']:.2f} N, {seen['replies']} replies, "
            f'{dev.stall_events} stalls, {dev.io_errors} USB errors')
        if seen['replies'] == 0 or dev.disconnected:
            raise CheckFailed(5, 'the device stopped answering while rendering force')
        say('   [ok]')
        step = 6
        dev.write((0.0, 0.0, 0.0))
        say('6. zero force' + ('' if keep_open else ', closing') + ': [ok] all steps passed')
        return 0
    except CheckFailed as exc:
        say(f'   [FAIL] {exc}')
        keep_open = False
        return exc.step
    except BaseException:
        keep_open = False
        raise
    finally:
        if not keep_open:
            dev.close()


# -- calibration ---------------------------------------------------------------------------------
def calibrated_counts_per_nm(used: float, commanded_extra: float, mass: float) -> float:
    """The motor scale [counts per N m] that makes ``commanded_extra`` N (the extra upward force
    commanded to hold ``mass`` kg) equal to the mass's weight (module doc)."""
    if not (mass > 0 and commanded_extra > 0 and used > 0):
        raise ValueError(f'calibration: expected a positive mass and a positive extra upward '
                         f'force, got mass {mass!r} kg, force {commanded_extra!r} N')
    return used * commanded_extra / (mass * G)


def calibrate(dev: FalconUSB, mass: float, wait: Callable[[str], None], say: Say = print,
              stiffness: float = 500.0, settle: float = 3.0, clock=time.monotonic,
              sleep=time.sleep) -> float:
    """Measure ``counts_per_nm`` with a known ``mass`` [kg] (the device must be connected and
    homed). ``wait(prompt)`` returns when the user has done what the prompt says (Enter).
    Returns the calibrated constant."""
    if not (math.isfinite(mass) and mass > 0):
        raise ValueError(f'calibration mass: expected a finite number > 0 kg, got {mass!r}')
    wait('hold the grip still near the middle, then let go of it and press Enter')
    anchor = dev.read(clock()).position
    hold = _spring_at(anchor, stiffness, dev.max_force)
    first = _settled_force(dev, hold, settle, clock, sleep)
    wait(f'hang the {mass:g} kg mass on the grip (no swinging), then press Enter')
    second = _settled_force(dev, hold, settle, clock, sleep)
    dev.write((0.0, 0.0, 0.0))
    extra = second[2] - first[2]  # device z is up
    say(f'commanded upward force without the mass {first[2]:.3f} N, with it {second[2]:.3f} N: '
        f'{extra:.3f} N for a weight of {mass * G:.3f} N')
    c = calibrated_counts_per_nm(dev.geometry.counts_per_nm, extra, mass)
    say(f'counts_per_nm: {dev.geometry.counts_per_nm:g} -> {c:.1f}')
    return c


def _spring_at(anchor, stiffness: float, limit: float):
    def force(p):
        f = tuple(stiffness * (a - v) for a, v in zip(anchor, p))
        n = math.sqrt(sum(v * v for v in f))
        return f if n <= limit else tuple(v * limit / n for v in f)
    return force


def _settled_force(dev: FalconUSB, force_of, seconds: float, clock, sleep) -> tuple:
    """Hold with ``force_of`` for ``seconds``; the mean commanded force over the last half [N]."""
    t0, acc, n = clock(), [0.0, 0.0, 0.0], 0
    while clock() - t0 < seconds:
        now = clock()
        s = dev.read(now)
        f = force_of(s.position)
        dev.write(f)
        if now - t0 >= seconds / 2:
            acc = [a + v for a, v in zip(acc, f)]
            n += 1
        sleep(0.001)
    if n == 0:
        raise FalconError('calibration: no samples (settle time too short)')
    return tuple(a / n for a in acc)


def write_counts_per_nm(params_file: str | Path, value: float) -> None:
    """Set ``counts_per_nm`` in the falcon_driver section of a ROS parameter file, keeping its
    comments (the line is replaced, or added under ``ros__parameters``)."""
    path = Path(params_file)
    text = path.read_text(encoding='utf-8')
    line = f'counts_per_nm: {value:.1f}'
    new, n = re.subn(r'^(\s*)counts_per_nm:.*$', lambda m: m.group(1) + line, text, count=1,
                     flags=re.M)
    if n == 0:
        m = re.search(r'^falcon_driver:\s*\n(\s*)ros__parameters:\s*\n(\s*)', text, flags=re.M)
        if m is None:
            raise ValueError(f'{path}: no falcon_driver: ros__parameters: section to write '
                             'counts_per_nm into')
        new = text[:m.end()] + line + '\n' + m.group(2) + text[m.end():]
    path.write_text(new, encoding='utf-8')


def geometry_with(counts_per_nm: float):
    """The default geometry with another motor scale."""
    return dataclasses.replace(GEOMETRY, counts_per_nm=float(counts_per_nm))
