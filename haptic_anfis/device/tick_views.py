"""The Python side of the compiled servo tick's buffers (no ROS): what the driver and
:class:`~.force_input.ForceInput` hold of the loop.

The rules (clamp, rate limit, watchdog, clutch / mark, local-model render, passivity) run in the
compiled tick (:mod:`.native_tick`) only. These classes write its input buffers (a command, a
model, enable / fault) and read its counters and published state:

- :class:`NativeSafety`: commands and faults in, the safety counters out;
- :class:`NativeRenderer`: local models in (checked and conditioned once per model here), the
  tick counts by render status out;
- :class:`NativeClutch`: the clutch / mark decisions of the newest published tick;
- :class:`NativeLoopStats`: the tick counters as a window of loop statistics, with the
  pose -> command latencies the driver records;
- :class:`NativeState`: one published tick.

``loop`` is the :class:`~.servo_native.NativeServoLoop` that owns the buffers (its ``ctl``,
``st``, ``cnt``, ``cfg``, ``cmd``, ``model``, ``last_state`` and ``last_out``).
"""
from __future__ import annotations

import math
import threading

import numpy as np

from ..interfaces import field_index
from . import native_tick as nt
from .buttons import ButtonEvents
from .falcon import DeviceState
from .local_model import (FALCON_MAX_STIFFNESS, APPROACH_RADIUS, RenderStats, accept_values,
                          rotating_mode, skew_vector, symmetric_part)
from .safety import IGNORED_DISABLED, OK, REJECTED_FRAME, REJECTED_NONFINITE, SafetyStats
from .stats import NEXT_TICK, LatencyHistogram

__all__ = ['NativeClutch', 'NativeLoopStats', 'NativeRenderer', 'NativeSafety', 'NativeState',
           'seq_read', 'seq_write', 'spectral_norm_sym']

#: where each field of the model buffer (:data:`~.native_tick.MODEL_SLOT`) sits in its values
_MODEL_AT = {name: field_index(nt.MODEL_SLOT, name) for name in nt.MODEL_SLOT.names}


def seq_write(buf: np.ndarray, values) -> None:
    """Seqlock write from Python: odd, the values, even (one writer per buffer)."""
    s = buf[0]
    buf[0] = s + 1.0
    buf[1:] = values
    buf[0] = s + 2.0


def seq_read(buf: np.ndarray) -> np.ndarray | None:
    """A consistent copy of a seqlock buffer the compiled loop writes (None after 100 tries)."""
    for _ in range(100):
        s1 = buf[0]
        c = buf.copy()
        if s1 % 2.0 == 0.0 and buf[0] == s1 and c[0] == s1:
            return c
    return None


def _check_positive(**values: float) -> None:
    """Raise ValueError naming the first value that is not a finite number > 0."""
    for name, v in values.items():
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f'{name}: expected a finite number > 0, got {v!r}')


def spectral_norm_sym(k) -> float:
    """The largest |eigenvalue| of the symmetric 3 x 3 ``k`` (9 values row-major) [N/m], by the
    trigonometric closed form (Smith 1961; plain floats, a few µs: once per received model)."""
    a00, a01, a02, _, a11, a12, _, _, a22 = k
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    if p2 <= 0.0:
        return abs(q)
    p = math.sqrt(p2 / 6.0)
    det = (b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02)
           + a02 * (a01 * a12 - b11 * a02))
    r = max(-1.0, min(1.0, det / (2.0 * p * p * p)))
    phi = math.acos(r) / 3.0
    l1 = q + 2.0 * p * math.cos(phi)
    l3 = q + 2.0 * p * math.cos(phi + 2.0943951023931957)
    return max(abs(l1), abs(l3))


class NativeState(DeviceState):
    """A published tick: :class:`DeviceState` plus the tick's wall-clock stamp [ns], its tissue
    position with the clutch [m], and the tick's monotonic time [s]."""

    def __init__(self, position, velocity, buttons, stamp_ns: int, tissue, t: float):
        object.__setattr__(self, 'position', position)
        object.__setattr__(self, 'velocity', velocity)
        object.__setattr__(self, 'buttons', buttons)
        object.__setattr__(self, 'stamp_ns', stamp_ns)
        object.__setattr__(self, 'tissue', tissue)
        object.__setattr__(self, 't', t)


class NativeLoopStats:
    """The compiled loop's tick counters (``cnt``) as a measurement window, with the
    pose -> command latencies the driver records (:meth:`latency`: a
    :class:`~.stats.LatencyHistogram`, constant memory). :meth:`reset` starts a new window by
    remembering the counters (the loop's own are never written here, but for its two maxima)."""

    def __init__(self, cnt: np.ndarray, period: float):
        self.period = float(period)
        self.latency_hist = LatencyHistogram()
        #: windows started by :meth:`reset` (a reader of two summaries knows whether they
        #: belong to one window, :mod:`.loop_health`)
        self.resets = 0
        self._cnt = cnt
        self._base = cnt.copy()

    def latency(self, seconds: float) -> None:
        """Record one pose -> command latency [s] (one writer thread: the command callback)."""
        self.latency_hist.add(seconds)

    def reset(self) -> None:
        """Start a new window: counters (from here) and latencies cleared."""
        self.resets += 1
        self.latency_hist.clear()
        # the two maxima restart with the window: the loop only ever raises them (a reset that
        # races with a tick's update loses that one tick's value)
        self._cnt[nt.CNT.max_gap_ns] = 0
        self._cnt[nt.CNT.max_force_un] = 0
        self._base = self._cnt.copy()

    def summary(self) -> dict:
        """The window's ticks, rate [Hz], lost periods, gaps, forces and latencies [ms]."""
        c, b, C = self._cnt.copy(), self._base, nt.CNT
        ticks = int(c[C.ticks] - b[C.ticks])
        t0 = (b[C.t_last_ns] if b[C.ticks] else c[C.t_first_ns]) * 1e-9
        span = c[C.t_last_ns] * 1e-9 - t0 if ticks > 0 else 0.0
        lat = self.latency_hist.snapshot()
        return {
            'ticks': ticks, 'seconds': span, 'rate_hz': ticks / span if span > 0 else 0.0,
            'deadline_misses': int(c[C.deadline_misses] - b[C.deadline_misses]),
            'periods_lost': int(c[C.periods_lost] - b[C.periods_lost]),
            'max_gap_ms': c[C.max_gap_ns] * 1e-6,
            'gaps_past_watchdog': int(c[C.long_gaps] - b[C.long_gaps]),
            'stats_resets': self.resets,
            'latency_n': lat['n'], 'latency_p50_ms': lat['p50'] * 1e3,
            'latency_p99_ms': lat['p99'] * 1e3, 'latency_max_ms': lat['max'] * 1e3,
            # answers taken by the tick right after their pose's (the latency counts to the tick
            # that takes the answer, so one period is the least it can be)
            'latency_next_tick_pct': 100.0 * self.latency_hist.fraction_at_most(
                NEXT_TICK * self.period),
            'max_force_N': c[C.max_force_un] * 1e-6,
            'passivity_limited': int(c[C.passivity_limited] - b[C.passivity_limited]),
            'observer_active': int(c[C.observer_active] - b[C.observer_active]),
            'ticks_held': int(c[C.held] - b[C.held]),
            'ticks_beyond': int(c[C.beyond] - b[C.beyond]),
            'ticks_taken_over': int(c[C.taken_over] - b[C.taken_over]),
        }


class NativeClutch:
    """The clutch as the driver sees it: the compiled tick runs the clutch / mark rules; this
    reports what the newest published tick decided."""

    def __init__(self, loop) -> None:
        self._loop = loop
        self._marks = 0
        self.held = False

    @property
    def marks(self) -> int:
        return int(self._loop.cnt[nt.CNT.marks])

    @property
    def clutches(self) -> int:
        return int(self._loop.cnt[nt.CNT.clutches])

    def update(self, buttons, mapped, now: float):
        """(tissue position of the newest tick, events: a mark since the previous call);
        ``mapped`` (the device position in the tissue frame) stands in before the first tick."""
        st = self._loop.last_state
        self.held = bool(self._loop.last_out[nt.OUT.held] > 0.5)
        ev = ButtonEvents()
        m = self.marks
        if m != self._marks:
            ev.mark = True
            self._marks = m
        return (st.tissue if st is not None else mapped), ev


class NativeSafety:
    """The compiled loop's safety layer as the driver and :class:`~.force_input.ForceInput`
    use it: commands (device frame) go into the command buffer; a non-finite one, a wrong frame
    or :meth:`reject` zeroes the force at once in the next tick. The clamp, rate limit and
    watchdog run in the compiled tick (its configuration holds the limits given here).

    Args:
        loop: the owning loop.
        max_force: device force limit [N], > 0.
        max_force_rate: largest change of the output per second [N/s], > 0.
        watchdog_timeout: command age [s] after which the force ramps to zero, > 0.
        frame_id: the frame commands must be expressed in ('' accepts any frame).
        max_dt: cap on the time step the rate limit uses [s], > 0.
    """

    def __init__(self, loop, max_force: float, max_force_rate: float, watchdog_timeout: float,
                 frame_id: str = 'tissue', max_dt: float = 0.005) -> None:
        _check_positive(max_force=max_force, max_force_rate=max_force_rate,
                        watchdog_timeout=watchdog_timeout, max_dt=max_dt)
        self.max_force, self.max_force_rate = float(max_force), float(max_force_rate)
        self.watchdog_timeout, self.max_dt = float(watchdog_timeout), float(max_dt)
        self.frame_id = frame_id
        self._loop = loop
        self._lock = threading.Lock()
        self._py = SafetyStats()  # what is counted here: commands, frames, the last refusal
        self._cmd = [0.0] * nt.CMD_LEN  # the next command, laid out as the command buffer

    @property
    def enabled(self) -> bool:
        return bool(self._loop.ctl[nt.CTL.enabled])

    @property
    def watchdog_tripped(self) -> bool:
        return bool(self._loop.st[nt.S.tripped] > 0.5)

    @property
    def stats(self) -> SafetyStats:
        """The counts made here with the compiled loop's (a new object each time)."""
        c, py = self._loop.cnt, self._py
        return SafetyStats(
            commands=py.commands, rejected_frame=py.rejected_frame, last_reject=py.last_reject,
            rejected_nonfinite=py.rejected_nonfinite + int(c[nt.CNT.rejected_nonfinite]),
            watchdog_trips=int(c[nt.CNT.watchdog_trips]),
            watchdog_trips_in_contact=int(c[nt.CNT.watchdog_trips_in_contact]),
            clamped=int(c[nt.CNT.clamped]), max_output=c[nt.CNT.max_force_un] * 1e-6)

    def start(self, now: float = 0.0) -> None:
        """Enable: the tick starts from zero force, the watchdog from its next tick."""
        ctl = self._loop.ctl
        ctl[nt.CTL.enabled] = 1
        ctl[nt.CTL.enable_gen] += 1

    def stop(self) -> None:
        """Disable: zero force from the next tick (until :meth:`start`)."""
        ctl = self._loop.ctl
        ctl[nt.CTL.enabled] = 0
        ctl[nt.CTL.enable_gen] += 1

    def command(self, force, now: float, frame_id: str | None = None, count: bool = True) -> str:
        """Offer a force command (3,) [N], device frame, whose time is ``now`` [s]; returns OK
        or why it was refused. ``count=False``: not counted in ``stats.commands``."""
        try:
            fx, fy, fz = (float(v) for v in force)
        except (TypeError, ValueError):
            fx = fy = fz = math.nan
        with self._lock:
            if not self.enabled:
                return IGNORED_DISABLED
            if count:
                self._py.commands += 1
            if not math.isfinite(fx + fy + fz):
                self._fault(REJECTED_NONFINITE)
                return REJECTED_NONFINITE
            if self.frame_id and frame_id is not None and frame_id != self.frame_id:
                self._py.rejected_frame += 1
                self._loop.ctl[nt.CTL.fault] += 1
                self._py.last_reject = f'{REJECTED_FRAME} {frame_id!r} (expected {self.frame_id!r})'
                return REJECTED_FRAME
            v, C = self._cmd, nt.CMD
            v[C.f0], v[C.f1], v[C.f2], v[C.t] = fx, fy, fz, float(now)
            seq_write(self._loop.cmd, v[1:])
            return OK

    def reject(self, why: str) -> None:
        """A non-finite input from elsewhere (a local model): zero at once in the next tick."""
        with self._lock:
            if self.enabled:
                self._fault(why)

    def _fault(self, why: str) -> None:
        self._py.rejected_nonfinite += 1
        self._py.last_reject = why
        self._loop.ctl[nt.CTL.fault] += 1


class NativeRenderer:
    """The local model's receiving side over the compiled loop: a model is checked and
    conditioned here (:func:`~.local_model.accept_values`, once per model) and written to the
    model buffer; the compiled tick renders it. The radii and times are the loop's
    configuration (``cfg``, written once): changing these attributes afterwards changes nothing
    the tick does.

    Args:
        loop: the owning loop.
        max_stiffness: tissue-frame stiffness bound [N/m]
            (:func:`~.local_model.tissue_stiffness_limit`).
        validity_time: a model older than this [s] (from its pose) is past its validity:
            held up to :attr:`max_age`, then expired.
        validity_radius: beyond this [m] from p0 the offset across the depth gradient is held.
        fresh_age: a model no older than this [s] counts as fresh.
        approach_radius: an approach plane renders zero further than this [m] from its point.
    """

    def __init__(self, loop, max_stiffness: float = FALCON_MAX_STIFFNESS / 1.5,
                 validity_time: float = 0.05, validity_radius: float = 0.005,
                 fresh_age: float = 0.0015, approach_radius: float = APPROACH_RADIUS) -> None:
        _check_positive(max_stiffness=max_stiffness, validity_time=validity_time,
                        validity_radius=validity_radius, fresh_age=fresh_age,
                        approach_radius=approach_radius)
        self.max_stiffness, self.validity_time = float(max_stiffness), float(validity_time)
        self.validity_radius, self.fresh_age = float(validity_radius), float(fresh_age)
        self.approach_radius = float(approach_radius)
        self.time: float | None = None  # the current model's time [s] (its pose's)
        self._loop = loop
        self._py = RenderStats()  # what is counted here: models taken, refused, clamped
        self._base = loop.cnt.copy()
        self._slot = [0.0] * nt.MODEL_LEN  # the next model, laid out as the model buffer

    @property
    def stats(self) -> RenderStats:
        """The models counted here with the loop's tick counts by status since
        :meth:`reset_stats` (a new object each time)."""
        c, b, C = self._loop.cnt, self._base, nt.CNT
        return RenderStats(
            models=self._py.models, rejected=self._py.rejected,
            stiffness_clamped=self._py.stiffness_clamped,
            ticks_fresh=int(c[C.fresh] - b[C.fresh]),
            ticks_extrapolated=int(c[C.extrapolated] - b[C.extrapolated]),
            ticks_expired=int(c[C.expired] - b[C.expired]),
            ticks_free=int(c[C.free] - b[C.free]), ticks_none=int(c[C.none] - b[C.none]),
            ticks_approach=int(c[C.approach] - b[C.approach]))

    def count_rejected(self) -> None:
        """Count a model refused before it reached :meth:`offer_values` (a malformed field)."""
        self._py.rejected += 1

    @property
    def max_age(self) -> float:
        """The oldest [s] a model is still rendered: the compiled tick's hold time (held while
        the probe stays near it; the validity time where there is no hold)."""
        return float(self._loop.cfg[nt.CFG.hold_time])

    def reset_stats(self) -> None:
        self._py = RenderStats()
        self._base = self._loop.cnt.copy()

    def clear(self) -> None:
        """Forget the model (the next ticks render nothing)."""
        self.time = None
        seq_write(self._loop.model, np.zeros(nt.MODEL_LEN - 1))

    def offer_values(self, v, time: float, checked: bool = False) -> None:
        """Take the flat values ``v`` (a message's ``position``,
        :data:`haptic_anfis.interfaces.LOCAL_MODEL`) as the newest model, whose time is
        ``time`` [s] (the driver's pose it answers): checked (unless ``checked``: the caller
        did), K conditioned, written to the model buffer.

        Raises:
            ValueError: a non-finite or malformed field (the model is not taken).
        """
        f0, p0, k, g, d, depth0, zero, contact = accept_values(v, self.max_stiffness, self._py,
                                                               checked)
        ks = symmetric_part(k)  # the tick adds the skew part w x e (held: without rotating mode)
        t = float(time)
        m, at = self._slot, _MODEL_AT  # a list by the buffer's fields: ~1 us, a record's ~15
        m[at['f']], m[at['p']], m[at['k']], m[at['g']], m[at['d']] = f0, p0, ks, g, d
        m[at['depth0']], m[at['zero']] = depth0, 1.0 if zero else 0.0
        m[at['contact']], m[at['t0']], m[at['valid']] = 1.0 if contact else 0.0, t, 1.0
        m[at['knorm']], m[at['w']] = spectral_norm_sym(ks), skew_vector(k)
        m[at['hold_skew']] = 0.0 if rotating_mode(k) else 1.0
        seq_write(self._loop.model, m[1:])
        self.time = t
        self._py.models += 1
