"""The servo tick's rules in plain Python: the test oracle the compiled tick
(``haptic_anfis.device.native_tick``) is held to, tick by tick.

- :class:`LocalModelRenderer`: the local force model's render (``haptic_anfis.device.local_model``'s
  module doc states the rules);
- :class:`ClutchMark`: the clutch / mark buttons (``haptic_anfis.device.buttons``' module doc);
- :class:`SafetyLayer`: clamp, rate limit, watchdog, command validation
  (``haptic_anfis.device.safety``'s module doc);
- :class:`ServoLoop`: a device ticked on a thread at a fixed period, or by the caller with
  chosen times, through a :class:`SafetyLayer` (each tick: read, ``on_state``, ``render``,
  the safety layer's output, write; the trace and statistics);
- :func:`render`: what the driver's servo tick offers the safety layer from a
  :class:`~haptic_anfis.device.force_input.ForceInput` in local-model mode (the render of the
  model at the tick's position), for a :class:`~haptic_anfis.device.servo.ServoLoop`'s
  ``render`` hook.

Times are seconds; lengths metres; forces newtons; tissue frame.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Callable

from haptic_anfis.device.buttons import CLUTCH, MARK, ButtonEvents
from haptic_anfis.device.local_model import (APPROACH_RADIUS, EXPIRED, EXTRAPOLATED,
                                             FALCON_MAX_STIFFNESS, FREE, FRESH, NONE, LocalModel,
                                             RenderStats, accept_values, across_beyond,
                                             hold_offset)
from haptic_anfis.device.falcon import RATED_FORCE, Device, DeviceState
from haptic_anfis.device.safety import (IGNORED_DISABLED, IGNORED_OLDER, OK, REJECTED_FRAME,
                                        REJECTED_NONFINITE, SafetyStats)
from haptic_anfis.device.stats import LoopStats
from haptic_anfis.device.trace import DISABLED, TickTrace
from haptic_anfis.realtime.scheduling import name_thread, schedule_servo_thread

__all__ = ['ClutchMark', 'LocalModelRenderer', 'SafetyLayer', 'ServoLoop', 'render']


def render(fi, state, now: float) -> int:
    """One tick of ``fi`` (a ForceInput whose renderer is a :class:`LocalModelRenderer`):
    local-model mode offers the safety layer the model's force at the tick's position (device
    frame, not counted as a command); returns the status code (-1 in zoh mode). Expired / no
    model: nothing is offered, so the safety layer holds the last force and its watchdog ramps
    it to zero."""
    if fi.mode != 'local_model':
        return -1
    m = fi.mapping
    f, status = fi.renderer.render(m.to_tissue(state.position), now)
    if f is not None:
        fi.safety.command(m.force_to_device(f), now, count=False)
    return status


class LocalModelRenderer:
    """Evaluates the newest accepted :class:`LocalModel` at the probe position every servo tick.

    ``offer`` runs on the thread that receives models, ``render`` on the servo thread; the model
    is swapped in as one reference (atomic under the GIL).

    Args:
        max_stiffness: tissue-frame stiffness bound [N/m] (``tissue_stiffness_limit``).
        validity_time: a model older than this [s] (from the time of its pose) is expired.
        validity_radius: a probe further than this [m] from the model's p0 is rendered with its
            offset across the depth gradient held at it (``hold_offset``).
        approach_radius: an approach model (depth 0: the plane ahead of a free probe) renders
            zero with the probe further than this [m] along the plane from its point
            (``across_beyond``).
        fresh_age: a model no older than this [s] counts as fresh (default 1.5 servo periods at
            1 kHz: it answers the previous tick's pose), older and valid as extrapolated.
    """

    def __init__(self, max_stiffness: float = FALCON_MAX_STIFFNESS / 1.5,
                 validity_time: float = 0.05, validity_radius: float = 0.005,
                 fresh_age: float = 0.0015, approach_radius: float = APPROACH_RADIUS) -> None:
        for name, v in (('max_stiffness', max_stiffness), ('validity_time', validity_time),
                        ('validity_radius', validity_radius), ('fresh_age', fresh_age),
                        ('approach_radius', approach_radius)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'{name}: expected a finite number > 0, got {v!r}')
        self.max_stiffness = float(max_stiffness)
        self.validity_time = float(validity_time)
        self.validity_radius = float(validity_radius)
        self.approach_radius = float(approach_radius)
        self.fresh_age = float(fresh_age)
        self.stats = RenderStats()
        self._m: tuple | None = None  # the prepared model (plain floats for the servo thread)
        self._values = None  # the current model's flat values
        self.time: float | None = None  # the current model's time [s] (its pose's)

    @property
    def max_age(self) -> float:
        """The oldest [s] a model is still rendered: its validity time (this renderer holds
        none)."""
        return self.validity_time

    def reset_stats(self) -> None:
        self.stats = RenderStats()

    def count_rejected(self) -> None:
        """Count a model refused before :meth:`offer_values` (a malformed field)."""
        self.stats.rejected += 1

    def clear(self) -> None:
        """Forget the model (the next ticks render nothing: status NONE)."""
        self._m = None
        self._values = None
        self.time = None

    def offer(self, m: LocalModel, checked: bool = False, time: float | None = None) -> None:
        """Accept ``m`` as the newest model (:meth:`offer_values` of ``m.values()``); ``time``:
        the model's time [s] if not ``m.time``.

        Raises:
            ValueError: a non-finite or malformed field (the model is not taken; the caller
            decides the safe output — zero force).
        """
        try:
            v = m.values()
        except ValueError:
            self.stats.rejected += 1
            raise
        self.offer_values(v, m.time if time is None else time, checked)

    def offer_values(self, v, time: float, checked: bool = False) -> None:
        """Accept the flat values ``v`` (26: :meth:`LocalModel.values`, a message's
        ``position``) as the newest model, whose time is ``time`` [s] (the driver: the time of
        its pose it answers; kept in :attr:`time`): checked (:func:`check_values`; unless
        ``checked``: the caller did), K conditioned (counted when the guard changed it by more
        than 1e-6 N/m). Plain floats throughout: this runs once per received model on the thread
        that shares the servo thread's GIL.

        Raises:
            ValueError: a non-finite or malformed field (the model is not taken).
        """
        f0, p0, k, g, d, depth0, zero, contact = accept_values(v, self.max_stiffness, self.stats,
                                                               checked)
        t = float(time)
        self._m = (f0, p0, (k[0:3], k[3:6], k[6:9]), g, d, depth0, zero, t, contact)
        self._values = v
        self.time = t
        self.stats.models += 1

    @property
    def model(self) -> LocalModel | None:
        """The current model (as received; its ``time`` is :attr:`time`), or None."""
        if self._m is None:
            return None
        return LocalModel.from_values(self._values, self.time)

    def render(self, p, now: float) -> tuple[tuple[float, float, float] | None, int]:
        """(force (3,) [N] or None, status) for the probe at ``p`` (3,) [m] at time ``now``.

        Status FRESH / EXTRAPOLATED: the model's force at p (beyond the validity radius: at p with
        its offset across the depth gradient held at the radius); FREE: zero (the model says no
        contact, p is out of the surface along the local normal, or an approach model's point is
        more than ``approach_radius`` away across the direction); EXPIRED (too old) and
        NONE (no model yet): None — the caller holds the last force and its watchdog ramps it.
        """
        m = self._m
        st = self.stats
        if m is None:
            st.ticks_none += 1
            return None, NONE
        f0, p0, k, g, d, depth0, zero_surface, t0, contact = m
        age = now - t0
        px, py, pz = p
        ex, ey, ez = px - p0[0], py - p0[1], pz - p0[2]
        if age > self.validity_time:
            st.ticks_expired += 1
            return None, EXPIRED
        depth = depth0 + g[0] * ex + g[1] * ey + g[2] * ez
        if not contact or depth <= 0.0:  # out along the local normal: zero at once, any distance
            st.ticks_free += 1
            return (0.0, 0.0, 0.0), FREE
        if depth0 == 0.0 and across_beyond(g[0], g[1], g[2], ex, ey, ez, self.approach_radius):
            st.ticks_free += 1   # an approach plane, away from its point (module doc)
            return (0.0, 0.0, 0.0), FREE
        if ex * ex + ey * ey + ez * ez > self.validity_radius ** 2:
            st.ticks_beyond += 1
            ex, ey, ez = hold_offset(g[0], g[1], g[2], ex, ey, ez, self.validity_radius)
        fresh = age <= self.fresh_age
        if fresh:
            st.ticks_fresh += 1
        else:
            st.ticks_extrapolated += 1
        if depth0 == 0.0:
            st.ticks_approach += 1
        k0, k1, k2 = k
        fx = f0[0] + k0[0] * ex + k0[1] * ey + k0[2] * ez
        fy = f0[1] + k1[0] * ex + k1[1] * ey + k1[2] * ez
        fz = f0[2] + k2[0] * ex + k2[1] * ey + k2[2] * ez
        if zero_surface and depth < depth0:
            # L(p_s), p_s = p - depth d on the tangent plane: subtract it with weight (1 - s)^2.
            sx, sy, sz = ex - depth * d[0], ey - depth * d[1], ez - depth * d[2]
            w = (1.0 - depth / depth0) ** 2
            fx -= w * (f0[0] + k0[0] * sx + k0[1] * sy + k0[2] * sz)
            fy -= w * (f0[1] + k1[0] * sx + k1[1] * sy + k1[2] * sz)
            fz -= w * (f0[2] + k2[0] * sx + k2[1] * sy + k2[2] * sz)
        return (fx, fy, fz), (FRESH if fresh else EXTRAPOLATED)


class ClutchMark:
    """Clutch / mark state machine, updated once per servo tick.

    Args:
        ramp_s: force ramp after the clutch is released and the gate opened [s] (> 0).
    """

    def __init__(self, ramp_s: float = 0.005):
        if not (math.isfinite(ramp_s) and ramp_s > 0):
            raise ValueError(f'ramp_s: expected a finite value > 0 s, got {ramp_s!r}')
        self.ramp_s = float(ramp_s)
        self.offset = (0.0, 0.0, 0.0)
        self.held = False
        self._mark_prev = False
        self._frozen = None            # tissue point held while the clutch is down
        self._wait_zero = False        # released inside the tissue: wait for a zero command
        self._ramp_start: float | None = None
        self.marks = 0
        self.clutches = 0

    def update(self, buttons, mapped, now: float) -> tuple[tuple[float, float, float], ButtonEvents]:
        """One tick: ``buttons`` (sequence of 0/1), ``mapped`` = mapping.to_tissue(device position)
        (3,) [m] without the clutch offset, ``now`` [s]. Returns (tissue position (3,) [m], events).
        """
        ev = ButtonEvents()
        clutch = len(buttons) > CLUTCH and bool(buttons[CLUTCH])
        mark = len(buttons) > MARK and bool(buttons[MARK])
        if clutch and not self.held:
            self.held, ev.clutch_pressed = True, True
            self.clutches += 1
            o = self.offset
            self._frozen = (mapped[0] + o[0], mapped[1] + o[1], mapped[2] + o[2])
        elif not clutch and self.held:
            self.held, ev.clutch_released = False, True
            f = self._frozen
            # The offset that keeps the probe where it was: the mapping followed the hand.
            self.offset = (f[0] - mapped[0], f[1] - mapped[1], f[2] - mapped[2])
            self._frozen = None
            self._wait_zero = True     # decided by the next command (see gain)
            self._ramp_start = None
        if mark and not self._mark_prev and not self.held:
            ev.mark = True
            self.marks += 1
        self._mark_prev = mark
        if self.held:
            return self._frozen, ev
        o = self.offset
        return (mapped[0] + o[0], mapped[1] + o[1], mapped[2] + o[2]), ev

    def tissue(self, mapped) -> tuple[float, float, float]:
        """The tissue position (3,) [m] for ``mapped`` = mapping.to_tissue(device position) in the
        current state, without updating it (the servo thread's renderer uses what :meth:`update`
        decided this tick)."""
        if self.held:
            return self._frozen
        o = self.offset
        return (mapped[0] + o[0], mapped[1] + o[1], mapped[2] + o[2])

    def gain(self, command, now: float) -> float:
        """Factor in [0, 1] for the force ``command`` (3,) [N] arriving at ``now`` [s]: 0 while
        held, 0 after a release inside the tissue until a zero command arrives, then a linear ramp
        over ``ramp_s``, then 1."""
        if self.held:
            return 0.0
        if self._wait_zero:
            if any(c != 0.0 for c in command):
                return 0.0              # still inside the tissue since the release
            self._wait_zero = False     # the probe left the tissue: ramp from the next contact
            self._ramp_start = now
            return 0.0
        if self._ramp_start is None:
            return 1.0
        a = (now - self._ramp_start) / self.ramp_s
        if a >= 1.0:
            self._ramp_start = None
            return 1.0
        return max(a, 0.0)


class SafetyLayer:
    """Clamp, rate limit, watchdog and command validation (see the module docstring).

    Args:
        max_force: device force limit [N], > 0 (the falcon driver passes its ``max_force``, default
            8.9 N, the Falcon's rated force).
        max_force_rate: largest change of the output per second [N/s], > 0.
        watchdog_timeout: command age [s] after which the force ramps to zero, > 0.
        frame_id: the frame commands must be expressed in ('' accepts any frame).
        max_dt: cap on the time step used by the rate limit [s] (a stalled caller must not earn
            a large jump).
    """

    def __init__(self, max_force: float = RATED_FORCE, max_force_rate: float = 1000.0,
                 watchdog_timeout: float = 0.010, frame_id: str = 'tissue',
                 max_dt: float = 0.005) -> None:
        for name, v in (('max_force', max_force), ('max_force_rate', max_force_rate),
                        ('watchdog_timeout', watchdog_timeout), ('max_dt', max_dt)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'{name}: expected a finite number > 0, got {v!r}')
        self.max_force = float(max_force)
        self.max_force_rate = float(max_force_rate)
        self.watchdog_timeout = float(watchdog_timeout)
        self.frame_id = frame_id
        self.max_dt = float(max_dt)
        self.stats = SafetyStats()
        self._lock = threading.Lock()
        self._enabled = False
        self._target = (0.0, 0.0, 0.0)
        self._out = (0.0, 0.0, 0.0)
        self._last_cmd: float | None = None
        self._last_out: float | None = None
        self._tripped = False

    # -- state ----------------------------------------------------------------------------------
    @property
    def enabled(self) -> bool:
        return self._enabled

    @property
    def watchdog_tripped(self) -> bool:
        return self._tripped

    def start(self, now: float) -> None:
        """Enable; the output starts at zero and the watchdog counts from ``now``."""
        with self._lock:
            self._enabled = True
            self._target = self._out = (0.0, 0.0, 0.0)
            self._last_cmd = None
            self._last_out = now
            self._tripped = False

    def stop(self) -> None:
        """Disable: the output is zero from now on (until :meth:`start`)."""
        with self._lock:
            self._enabled = False
            self._target = self._out = (0.0, 0.0, 0.0)

    # -- input ----------------------------------------------------------------------------------
    def command(self, force, now: float, frame_id: str | None = None, count: bool = True) -> str:
        """Offer a force command (3,) [N] whose time is ``now`` (the time of the pose it answers,
        or its arrival); returns OK or why it was refused. ``count=False``: not counted in
        ``stats.commands`` (the local model feeds its force every servo tick)."""
        try:
            fx, fy, fz = (float(v) for v in force)
        except (TypeError, ValueError):
            fx = fy = fz = math.nan
        with self._lock:
            if not self._enabled:
                return IGNORED_DISABLED
            if count:
                self.stats.commands += 1
            if not math.isfinite(fx + fy + fz) or not all(map(math.isfinite, (fx, fy, fz))):
                self.stats.rejected_nonfinite += 1
                self._fault(REJECTED_NONFINITE)
                return REJECTED_NONFINITE
            if self.frame_id and frame_id is not None and frame_id != self.frame_id:
                self.stats.rejected_frame += 1
                self._fault(f'{REJECTED_FRAME} {frame_id!r} (expected {self.frame_id!r})')
                return REJECTED_FRAME
            if self._last_cmd is not None and now < self._last_cmd:
                return IGNORED_OLDER
            self._target = (fx, fy, fz)
            self._last_cmd = now
            self._tripped = False
            return OK

    def reject(self, why: str) -> None:
        """A non-finite input from elsewhere (e.g. a local force model): counted as a non-finite
        command, and the output drops to zero at once as for one."""
        with self._lock:
            if not self._enabled:
                return
            self.stats.rejected_nonfinite += 1
            self._fault(why)

    def _fault(self, why: str) -> None:
        self._target = self._out = (0.0, 0.0, 0.0)
        self._last_cmd = None  # no valid command: the watchdog stays tripped until one comes
        self.stats.last_reject = why

    # -- output ---------------------------------------------------------------------------------
    def output(self, now: float) -> tuple[float, float, float]:
        """The force to apply now [N]: finite, magnitude <= max_force, rate-limited."""
        with self._lock:
            if not self._enabled:
                return (0.0, 0.0, 0.0)
            last = self._last_out if self._last_out is not None else now
            gap = now - last
            dt = min(max(gap, 0.0), self.max_dt)
            self._last_out = now
            age = math.inf if self._last_cmd is None else now - self._last_cmd
            if age > self.watchdog_timeout:
                if not self._tripped and self._last_cmd is not None:
                    self.stats.watchdog_trips += 1
                    if self._target != (0.0, 0.0, 0.0):
                        self.stats.watchdog_trips_in_contact += 1
                self._tripped = True
                self._target = (0.0, 0.0, 0.0)
                if gap > self.watchdog_timeout:
                    # The caller itself stalled longer than the watchdog (a paused process): the
                    # ramp's time has passed already; zero now, not a ramp from a stale force.
                    self._out = (0.0, 0.0, 0.0)
            tx, ty, tz = self._target
            tn = math.sqrt(tx * tx + ty * ty + tz * tz)
            if tn > self.max_force:
                self.stats.clamped += 1
                s = self.max_force / tn
                tx, ty, tz = tx * s, ty * s, tz * s
            ox, oy, oz = self._out
            dx, dy, dz = tx - ox, ty - oy, tz - oz
            dn = math.sqrt(dx * dx + dy * dy + dz * dz)
            step = self.max_force_rate * dt
            if dn > step:
                s = step / dn
                dx, dy, dz = dx * s, dy * s, dz * s
            ox, oy, oz = ox + dx, oy + dy, oz + dz
            on = math.sqrt(ox * ox + oy * oy + oz * oz)
            if on > self.max_force:  # rounding guard: never above the limit
                s = self.max_force / on
                ox, oy, oz = ox * s, oy * s, oz * s
                on = self.max_force
            self._out = (ox, oy, oz)
            if on > self.stats.max_output:
                self.stats.max_output = on
            return self._out


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
