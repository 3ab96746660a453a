"""The Python servo loop: its own thread, fixed period, absolute deadlines (no ROS).

No driver runs it: the compiled tick (:mod:`.native_tick`, :mod:`.servo_native`) is the servo
tick of every backend. It renders the threshold test's spring (:mod:`.stiffness_press`: a plane
of known stiffness, no local model) on a device through :class:`~.safety.SafetyLayer`, and runs
the device tests and the USB jitter benchmark.

Each tick: read the device, hand the reading to ``on_state`` (the driver publishes it), let
``render`` offer the safety layer this tick's force (the local force model, evaluated at this
tick's position), ask the safety layer for the force and write it to the device; optionally append
the tick to a :class:`~.trace.TickTrace`. Sleeping to absolute deadlines absorbs
``time.sleep`` overshoot; a tick that starts more than a period late counts as a deadline miss and
the schedule re-synchronises (no burst of catch-up ticks). On exit the safety layer is stopped and
the device gets zero force.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Callable

from .falcon import Device, DeviceState
from .safety import SafetyLayer
from .stats import LoopStats
from .trace import DISABLED, TickTrace
from ..realtime.scheduling import name_thread, schedule_servo_thread


class ServoLoop:
    """Run ``device`` at ``rate`` Hz on a daemon thread through ``safety``.

    ``on_state(state, force, now)`` runs on the servo thread after each read; ``force`` is the
    force applied in the previous tick (device frame). Exceptions in it are counted and the loop
    keeps running (``errors``; the last one in ``last_error``). ``render(state, now) -> int``
    runs next (same error handling) and returns the tick's status code, kept in ``status`` and
    written to ``trace`` (a :class:`~.trace.TickTrace`, or None) with the applied force.
    """

    def __init__(self, device: Device, safety: SafetyLayer, rate: float = 1000.0,
                 on_state: Callable[[DeviceState, tuple, float], None] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 render: Callable[[DeviceState, float], int] | None = None,
                 trace: TickTrace | None = None, priority: int = 0):
        if not rate > 0:
            raise ValueError(f'rate: expected > 0 Hz, got {rate!r}')
        if not 0 <= priority <= 99:
            raise ValueError(f'priority: expected 0 (normal scheduling) to 99, got {priority!r}')
        self.priority = int(priority)
        #: how the servo thread is scheduled (set by the thread as it starts; see set_realtime)
        self.scheduling = ''
        self._scheduled = threading.Event()
        self.device, self.safety, self.on_state, self.clock = device, safety, on_state, clock
        self.render, self.trace, self.status = render, trace, -1
        self.period = 1.0 / rate
        self.stats = LoopStats(period=self.period,
                               watchdog=getattr(safety, 'watchdog_timeout', math.inf))
        self.errors = 0
        self.last_error: BaseException | None = None
        self.force = (0.0, 0.0, 0.0)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        now = self.clock()
        self.device.open(now)
        self.safety.start(now)
        self._thread = threading.Thread(target=self._run, name='servo', daemon=True)
        self._thread.start()
        self._scheduled.wait(1.0)  # so that the caller can log how the thread runs

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        self.safety.stop()
        self.device.write((0.0, 0.0, 0.0))
        self.device.close()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def tick(self, now: float) -> None:
        """One servo cycle at time ``now`` (also usable without the thread, e.g. in tests)."""
        state = self.device.read(now)
        if self.on_state is not None:
            try:
                self.on_state(state, self.force, now)
            except Exception as exc:  # a publishing hiccup must not stop the servo
                self.errors += 1
                self.last_error = exc
        if self.render is not None:
            try:
                self.status = self.render(state, now)
            except Exception as exc:  # as above: the safety layer's watchdog covers a failure
                self.errors += 1
                self.last_error = exc
        f = self.safety.output(now)
        self.device.write(f)
        self.force = f
        if self.trace is not None:
            self.trace.add(now, state.position, f,
                           self.status if self.safety.enabled else DISABLED)
        n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) ** 0.5
        if n > self.stats.max_force:
            self.stats.max_force = n
        self.stats.tick(now)

    def _run(self) -> None:
        name_thread('servo-tick')
        self.scheduling = schedule_servo_thread(self.priority)
        self._scheduled.set()
        period, clock, stop = self.period, self.clock, self._stop
        deadline = clock()
        while not stop.is_set():
            now = clock()
            if now - deadline > period:
                self.stats.deadline_misses += 1
                deadline = now  # re-synchronise
            try:
                self.tick(now)
            except Exception as exc:  # a device read/write failure: zero force, keep the period
                self.errors += 1
                self.last_error = exc
                self.safety.stop()
                self.safety.start(now)  # starts at zero; the watchdog needs a new command
                try:
                    self.device.write((0.0, 0.0, 0.0))
                except Exception:
                    pass
            deadline += period
            delay = deadline - clock()
            if delay > 0:
                time.sleep(delay)
        self.safety.stop()
        self.device.write((0.0, 0.0, 0.0))
