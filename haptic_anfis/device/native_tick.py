"""The servo tick compiled with numba ``nogil``: device, local model, clutch, safety, passivity.

One function, :func:`run`, is the whole servo loop: a Python thread calls it once and it returns
only when told to stop, so the thread holds no interpreter lock (GIL) for the loop's whole life
(the executors, the recorder and the garbage collector can hold it for 14-169 ms).
It sleeps to absolute 1 ms deadlines with ``clock_nanosleep`` and reads the clock with
``clock_gettime`` (libc through ctypes: numba compiles those calls to plain C calls). Each tick
(:func:`tick`, also called alone by the tests with a chosen time):

1. Read the device: the simulated Falcon's handle (mass-spring-damper hand pulled to the scripted
   target, semi-implicit Euler, at most ``dt_max`` steps; the script sampled into arrays).
2. The clutch / mark buttons (:mod:`.buttons`' rules; ``ClutchMark`` in the tests' oracle).
3. Render: the newest local model (:mod:`.local_model`'s rules: depth along the indentation
   direction, onset correction, expiry by age, the offset across held beyond the radius) or the
   newest force command (zero-order hold), in the device frame. A model older than its validity
   time but younger than ``hold_time`` is still rendered (counted as ``held``): the tissue does
   not move, so its local linearisation stays right near p0, and an upstream stall (force
   server, contact detector, the bridge) does not drop the force to 0 N. Only within
   ``hold_radius`` of p0, though: with the probe further, a held model that would press on it
   is expired for that tick (:data:`.local_model.HOLD_RADIUS`; back inside, it is rendered
   again: the tissue has not moved). Beyond the validity
   radius the depth is followed exactly and the offset across the indentation direction held at
   the radius (:func:`.local_model.hold_offset`, counted as ``beyond``): a late model under a
   fast stroke does not drop the force to 0 N either; an approach model (the plane ahead of a
   free probe) past ``approach_radius`` along its plane renders zero instead
   (:func:`.local_model.across_beyond`). The stiffness's skew part (the tissue force turning with
   the probe) is rendered while the model is valid; a held model keeps it
   only where K has no rotating mode (:func:`.local_model.rotating_mode`): a free handle could
   spiral out along one. A new model that disagrees with the old one at the probe by more than
   :data:`BLEND_DEADBAND` is not taken as a step: the excess is ramped out over the old
   model's age (at most ``blend_time``), so a model that comes late does not jolt the hand
   (:func:`_render_blended`; a release is never faded).
4. Passivity: the model's stiffness is limited by the MEASURED tick period ``T``:
   ``K <= 2 (b - |B|) / T`` with ``b`` the device's damping and ``B`` the rendered damping
   (here 0) — Colgate & Schenkel 1997 (J. Robotic Systems 14(1):37-47), the discrete-time
   passivity condition of a virtual wall, ``b > K T / 2 + |B|`` — with ``T`` the energy-weighted
   mean of the last ``passivity_window`` (50 ms) of periods (:func:`_passivity_period`: one
   late tick lowers the stiffness a little, at once, and it comes back over about the window,
   where the last gap alone would turn one late tick into a one-tick force step). Optional
   passivity observer / controller (Hannaford & Ryu 2002, IEEE T-RO 18(1):1-10): the energy the
   rendered port put out so far; when it turns negative a damping force takes it back.
5. Safety (:mod:`.safety`'s rules; ``SafetyLayer`` in the tests' oracle): non-finite -> zero at
   once, watchdog on the command age (zero at once after a stall longer than the watchdog), rate
   limit, clamp to ``max_force``.
6. Write the device, the tick's trace row, the published state (a seqlock), the counters.

Exchange with Python (:mod:`.servo_native`) is through numpy arrays only, passed as a few named
groups (the configuration, the loop's state and counters, the :class:`Script` and the
:class:`Buffers`): seqlock buffers for the command, the model and the published state (the
writer makes the sequence number odd, writes, makes it even; the reader retries when it
changed), a ring for the trace, int64 counters. A libc
``memcpy`` through ctypes is an opaque call the compiler can neither reorder stores across nor
elide: it orders each seqlock. Times are seconds on CLOCK_MONOTONIC (Python's ``time.monotonic``),
lengths metres, forces newtons.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import enum
import hashlib
import inspect
from typing import NamedTuple

import numba as nb
from llvmlite import binding as llvm
from numba.extending import register_jitable
import numpy as np

from .local_model import across_beyond, hold_offset, split_offset
from .stats import periods_lost_in
from .trace import DISABLED

#: Plain functions of the numba-free modules compiled into the kernels below (registered here).
INLINED = (split_offset, hold_offset, across_beyond, periods_lost_in)
for _f in INLINED:
    register_jitable(_f)
#: numba's cache keys a kernel on this file alone, not on the functions it calls from others: a
#: change to one of INLINED must change this file, or a stale kernel runs. This is
#: :func:`inlined_source_hash` (test_servo_native checks it; update it when they change).
INLINED_SOURCE_HASH = '5bbbc5f8411c2e53'


def inlined_source_hash() -> str:
    """The first 16 hex digits of the SHA-256 of :data:`INLINED`'s source code."""
    h = hashlib.sha256()
    for f in INLINED:
        h.update(inspect.getsource(f).encode())
    return h.hexdigest()[:16]

__all__ = ['CFG', 'CNT', 'OUT', 'CMD', 'HAND', 'CMD_LEN', 'MODEL_LEN', 'MODEL_SLOT', 'STATE_LEN',
           'CTL', 'TRACE_COLS', 'Script', 'Buffers', 'CFG_LEN', 'CTL_LEN', 'HAND_LEN', 'OUT_LEN',
           'CNT_LEN', 'SCRATCH_LEN', 'LOCK_LEN',
           'tick', 'run', 'clock_now', 'new_state']

_libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6', use_errno=True)


def _external(name: str, sig) -> object:
    """libc's ``name`` as a numba external function: the compiled code calls the symbol by name
    (resolved through llvmlite's symbol table, so the kernel can be cached, unlike a ctypes
    pointer). Pointer arguments are declared int64 (the same register on x86-64 / aarch64):
    numba passes ``array.ctypes.data`` as an integer."""
    sym = f'haptic_anfis_{name}'
    fn = getattr(_libc, name, None)
    if fn is None:  # glibc < 2.34 keeps the pthread functions in libpthread
        fn = getattr(ctypes.CDLL(ctypes.util.find_library('pthread') or 'libpthread.so.0'), name)
    llvm.add_symbol(sym, ctypes.cast(fn, ctypes.c_void_p).value)
    return nb.types.ExternalFunction(sym, sig)


_i32, _i64 = nb.types.int32, nb.types.int64
_clock_gettime = _external('clock_gettime', _i32(_i32, _i64))
_clock_nanosleep = _external('clock_nanosleep', _i32(_i32, _i32, _i64, _i64))
_memcpy = _external('memcpy', _i64(_i64, _i64, _i64))
_mutex_trylock = _external('pthread_mutex_trylock', _i32(_i64))
_mutex_lock = _external('pthread_mutex_lock', _i32(_i64))
_mutex_unlock = _external('pthread_mutex_unlock', _i32(_i64))
CLOCK_REALTIME, CLOCK_MONOTONIC, TIMER_ABSTIME = 0, 1, 1


def _index(name: str, names: str) -> type:
    """An IntEnum of consecutive indices 0, 1, ... for the space-separated ``names`` (numba reads
    its members as integer constants)."""
    return enum.IntEnum(name, names, start=0)


#: The model buffer (float64 seqlock), its one layout: seq; the model as the tick renders it, in
#: the tissue frame: f [N] and p [m] (F0 and p0), k (9: the conditioned stiffness's symmetric
#: part, row-major [N/m]), g (the depth's gradient), d (the indentation direction), depth0 [m],
#: zero (1: zero at the surface), contact (1: renders past its plane), t0 (its pose's time [s]),
#: valid (0 = cleared), knorm (the symmetric part's spectral norm [N/m]), w (3: its skew part,
#: A e = w x e [N/m]; local_model module doc), hold_skew (1: a held model keeps the skew part, K
#: having no rotating mode). Python writes it by field name
#: (:class:`~.servo_native.NativeRenderer`); the loop state holds a copy of all but ``seq`` as
#: :data:`S`'s ``m_<field><i>`` members, whose names and order derive from it.
MODEL_SLOT = np.dtype([('seq', 'f8'), ('f', 'f8', 3), ('p', 'f8', 3), ('k', 'f8', 9),
                       ('g', 'f8', 3), ('d', 'f8', 3), ('depth0', 'f8'), ('zero', 'f8'),
                       ('contact', 'f8'), ('t0', 'f8'), ('valid', 'f8'), ('knorm', 'f8'),
                       ('w', 'f8', 3), ('hold_skew', 'f8')])
MODEL_LEN = MODEL_SLOT.itemsize // 8


def _flat_names(layout: np.dtype) -> list[str]:
    """A float64 record layout's flat names: a scalar field's name, a vector's ``name0``, ..."""
    out: list[str] = []
    for name in layout.names:
        sub = layout[name]
        out += [name] if not sub.shape else [f'{name}{i}' for i in range(sub.shape[0])]
    return out


class Script(NamedTuple):
    """The simulated hand's script, sampled (read only): ``times`` (n,) [s], ``points`` (n, 3)
    tissue frame [m], ``buttons`` (n - 1, 2) int64 per segment, or (0, 2) for none
    (:func:`~.servo_native.script_arrays`)."""

    times: np.ndarray
    points: np.ndarray
    buttons: np.ndarray


class Buffers(NamedTuple):
    """The buffers the loop shares with Python (numba reads a named tuple's fields by name):
    ``hand`` (:data:`HAND_LEN`), ``cmd`` (:data:`CMD_LEN`) and ``model`` (:data:`MODEL_SLOT`)
    seqlocks Python writes, ``ctl`` (:data:`CTL`, int64), ``out`` (:data:`OUT`, a seqlock the
    loop writes) and the ``trace`` ring ((rows, :data:`TRACE_COLS`); 0 rows: no trace)."""

    hand: np.ndarray
    cmd: np.ndarray
    model: np.ndarray
    ctl: np.ndarray
    out: np.ndarray
    trace: np.ndarray


#: configuration (float64), written once before the loop starts
CFG = _index('CFG', 'period max_force max_force_rate watchdog max_dt validity_time validity_radius '
             'fresh_age max_stiffness scale ox oy oz force_scale hand_m hand_k hand_c half '
             'dt_max max_catch_up ramp damping mode observer loop dev_max_force hold_time device '
             'approach_radius hold_radius blend_time passivity_window')
#: the loop's own state (float64)
S = _index('S', 'x0 x1 x2 v0 v1 v2 f0 f1 f2 t_dev t_open script_off '
           'enabled target0 target1 target2 out0 out1 out2 last_cmd last_out tripped '
           'held frozen0 frozen1 frozen2 off0 off1 off2 wait_zero ramp_start mark_prev '
           'energy t_prev pt1 pt2 cmd_seen model_seen fault_seen enable_seen status '
           + ' '.join(f'm_{n}' for n in _flat_names(MODEL_SLOT)[1:]) + ' bl0 bl1 bl2 bl_tau')
STATE_LEN = len(S)
#: the state's copy of the model buffer's first field after ``seq``
_M0 = S['m_' + _flat_names(MODEL_SLOT)[1]]
#: command buffer (float64 seqlock): seq, force (3,) device frame [N], its pose's time [s]
CMD = _index('CMD', 'seq f0 f1 f2 t')
CMD_LEN = len(CMD)
#: control (int64): stop, release (the held script), fault generation (zero at once),
#: enable generation and enabled (NativeSafety.start / stop)
CTL = _index('CTL', 'stop release fault enable_gen enabled external')
#: external hand target (float64 seqlock; ``ctl[external]`` = 1): seq, its time [s], target (3,)
#: device frame [m], its velocity (3,) [m/s], buttons 0 and 1 (a script only Python can play).
#: With ``cfg[device]`` = 1 (a real device read by the servo process before each tick, see
#: :mod:`.device_process`) the same layout holds the device's MEASURED position and velocity.
HAND = _index('HAND', 'seq t x0 x1 x2 v0 v1 v2 b0 b1')
HAND_LEN = len(HAND)
#: the hand target is extrapolated from the newest one for at most this long [s], then held
HAND_EXTRAPOLATE = 0.02
#: published state (float64 seqlock): seq, t, device position, velocity, tissue position (with
#: the clutch), applied force (device frame), status, clutch held, buttons 0..3, stamp [ns] as
#: two int32 halves are not needed: the realtime stamp is published in :data:`CNT`'s ``stamp``
OUT = _index('OUT', 'seq t p0 p1 p2 v0 v1 v2 q0 q1 q2 f0 f1 f2 status held b0 b1 b2 b3 stamp_hi '
             'stamp_lo')
#: counters (int64), written by the loop only
CNT = _index('CNT', 'ticks periods_lost deadline_misses watchdog_trips watchdog_trips_in_contact '
             'clamped rejected_nonfinite none fresh extrapolated expired free approach '
             'passivity_limited observer_active max_gap_ns max_force_un marks clutches '
             'trace_w t_first_ns t_last_ns running held deadline_ns beyond claim_ns claim_at_ns '
             'gen taken_over long_gaps')
#: trace row: t, device position (3,), applied force (3,) device frame, status (as TickTrace)
TRACE_COLS = 8
CFG_LEN, CTL_LEN, OUT_LEN, CNT_LEN = len(CFG), len(CTL), len(OUT), len(CNT)
#: the workers' mutex: int64 words holding a zeroed ``pthread_mutex_t`` (40 bytes on x86-64, 48
#: on aarch64; all-zero is glibc's PTHREAD_MUTEX_INITIALIZER)
LOCK_LEN = 16
#: scratch array length (the largest seqlock buffer)
SCRATCH_LEN = max(CMD_LEN, MODEL_LEN, OUT_LEN)

NONE, FRESH, EXTRAPOLATED, EXPIRED, FREE = 0, 1, 2, 3, 4  # local_model's status codes
#: [N] the part of a step between two models that is taken at once (:func:`_render_blended`):
#: models on time differ by less (hundredths of a newton), so they are rendered as they come; a
#: step of s leaves the 50 ms mean by ~s / 2, a ripple window (> 0.1 N) from 0.2 N
BLEND_DEADBAND = 0.05


def new_state() -> np.ndarray:
    """A fresh loop state (disabled safety, no model, no command)."""
    st = np.zeros(STATE_LEN)
    st[S.last_cmd] = np.nan
    st[S.ramp_start] = np.nan
    st[S.script_off] = np.nan
    st[S.t_dev] = np.nan
    st[S.t_prev] = np.nan
    st[S.cmd_seen] = st[S.model_seen] = 0.0
    return st


@nb.njit(nogil=True, cache=True)
def clock_now(ts) -> float:
    """CLOCK_MONOTONIC [s] (``ts``: an int64 (2,) scratch array)."""
    _clock_gettime(CLOCK_MONOTONIC, ts.ctypes.data)
    return ts[0] + ts[1] * 1e-9


@nb.njit(nogil=True, cache=True)
def _script_point(cfg, st, script, t):
    """The hand target (device frame, clipped to the workspace) and the segment index at device
    time ``t`` [s] (script held at its start until released: ``script_off`` NaN)."""
    times, points = script.times, script.points
    off = st[S.script_off]
    tl = 0.0 if off != off else max(t - off, 0.0)
    n = times.shape[0]
    dur = times[n - 1]
    if cfg[CFG.loop] > 0.5 and dur > 0.0:
        tl = tl % dur
    else:
        tl = min(max(tl, 0.0), dur)
    i = np.searchsorted(times, tl, side='right') - 1
    if i < 0:
        i = 0
    if i >= n - 1:
        i = n - 1
        a = 0.0
        j = i
    else:
        t0, t1 = times[i], times[i + 1]
        a = (tl - t0) / (t1 - t0) if t1 > t0 else 1.0
        j = i + 1
    h = cfg[CFG.half]
    sc = cfg[CFG.scale]
    out = np.empty(3)
    for k in range(3):
        p = points[i, k] + a * (points[j, k] - points[i, k])
        d = (p - cfg[CFG.ox + k]) / sc
        out[k] = min(max(d, -h), h)
    return out, min(i, max(n - 2, 0))


@nb.njit(nogil=True, cache=True)
def _device_read(cfg, st, script, buf, now):
    """Advance the simulated handle to ``now`` (or take a real device's reading from
    ``buf.hand``); returns (b0, b1) buttons."""
    ctl, hand, buttons = buf.ctl, buf.hand, script.buttons
    if cfg[CFG.device] > 0.5:  # a real device: its servo process read it just before this tick
        if st[S.t_dev] != st[S.t_dev]:
            st[S.t_open] = now
        st[S.t_dev] = now
        for k in range(3):
            st[S.x0 + k] = hand[HAND.x0 + k]
            st[S.v0 + k] = hand[HAND.v0 + k]
        return int(hand[HAND.b0]), int(hand[HAND.b1])
    if st[S.t_dev] != st[S.t_dev]:
        st[S.t_dev] = now
        st[S.t_open] = now
    if st[S.script_off] != st[S.script_off] and ctl[CTL.release] != 0:
        st[S.script_off] = now - st[S.t_open]
    span = min(max(now - st[S.t_dev], 0.0), cfg[CFG.max_catch_up])
    st[S.t_dev] = now
    if ctl[CTL.external] != 0:
        target = np.empty(3)
        dt = min(max(now - hand[HAND.t], 0.0), HAND_EXTRAPOLATE)
        h = cfg[CFG.half]
        for k in range(3):
            target[k] = min(max(hand[HAND.x0 + k] + hand[HAND.v0 + k] * dt, -h), h)
        hb0, hb1 = int(hand[HAND.b0]), int(hand[HAND.b1])
    else:
        target, seg = _script_point(cfg, st, script, now - st[S.t_open])
    if span > 0.0:
        n = max(1, int(np.ceil(span / cfg[CFG.dt_max] - 1e-9)))
        dt = span / n
        m, k, c, h = cfg[CFG.hand_m], cfg[CFG.hand_k], cfg[CFG.hand_c], cfg[CFG.half]
        for _ in range(n):
            for i in range(3):
                a = (k * (target[i] - st[S.x0 + i]) - c * st[S.v0 + i] + st[S.f0 + i]) / m
                st[S.v0 + i] += a * dt
                st[S.x0 + i] += st[S.v0 + i] * dt
                if st[S.x0 + i] > h:
                    st[S.x0 + i] = h
                    st[S.v0 + i] = min(st[S.v0 + i], 0.0)
                elif st[S.x0 + i] < -h:
                    st[S.x0 + i] = -h
                    st[S.v0 + i] = max(st[S.v0 + i], 0.0)
    if ctl[CTL.external] != 0:
        return hb0, hb1
    if st[S.script_off] != st[S.script_off] or buttons.shape[0] == 0:
        return 0, 0
    return int(buttons[seg, 0]), int(buttons[seg, 1])


@nb.njit(nogil=True, cache=True)
def _device_write(cfg, st, fx, fy, fz):
    """The motor force (device frame), clamped to the device's own limit, NaN -> 0."""
    n = np.sqrt(fx * fx + fy * fy + fz * fz)
    if not np.isfinite(n):
        fx = fy = fz = 0.0
    elif n > cfg[CFG.dev_max_force]:
        s = cfg[CFG.dev_max_force] / n
        fx, fy, fz = fx * s, fy * s, fz * s
    st[S.f0], st[S.f1], st[S.f2] = fx, fy, fz


@nb.njit(nogil=True, cache=True)
def _clutch(st, cnt, b0, b1, m0, m1, m2):
    """The clutch / mark update: the tissue position (3,) for ``m`` = mapped device position; counts
    clutches and marks (a mark event: ``cnt[marks]`` goes up)."""
    clutch = b0 != 0
    mark = b1 != 0
    if clutch and st[S.held] < 0.5:
        st[S.held] = 1.0
        cnt[CNT.clutches] += 1
        st[S.frozen0] = m0 + st[S.off0]
        st[S.frozen1] = m1 + st[S.off1]
        st[S.frozen2] = m2 + st[S.off2]
    elif not clutch and st[S.held] > 0.5:
        st[S.held] = 0.0
        st[S.off0] = st[S.frozen0] - m0
        st[S.off1] = st[S.frozen1] - m1
        st[S.off2] = st[S.frozen2] - m2
        st[S.wait_zero] = 1.0
        st[S.ramp_start] = np.nan
    if mark and st[S.mark_prev] < 0.5 and st[S.held] < 0.5:
        cnt[CNT.marks] += 1
    st[S.mark_prev] = 1.0 if mark else 0.0
    if st[S.held] > 0.5:
        return st[S.frozen0], st[S.frozen1], st[S.frozen2]
    return m0 + st[S.off0], m1 + st[S.off1], m2 + st[S.off2]


@nb.njit(nogil=True, cache=True)
def _gain(cfg, st, nonzero, now):
    """The clutch's gain for this tick's force (``nonzero``: it is not exactly zero)."""
    if st[S.held] > 0.5:
        return 0.0
    if st[S.wait_zero] > 0.5:
        if nonzero:
            return 0.0
        st[S.wait_zero] = 0.0
        st[S.ramp_start] = now
        return 0.0
    r = st[S.ramp_start]
    if r != r:
        return 1.0
    a = (now - r) / cfg[CFG.ramp]
    if a >= 1.0:
        st[S.ramp_start] = np.nan
        return 1.0
    return max(a, 0.0)


@nb.njit(nogil=True, cache=True)
def _safety_reset(st, now, enabled):
    st[S.enabled] = 1.0 if enabled else 0.0
    _drop_fade(st)
    for i in range(3):
        st[S.target0 + i] = 0.0
        st[S.out0 + i] = 0.0
    st[S.last_cmd] = np.nan
    st[S.last_out] = now
    st[S.tripped] = 0.0


@nb.njit(nogil=True, cache=True)
def _command(st, fx, fy, fz, t):
    """Take a finite force command (device frame) whose time is ``t``."""
    if st[S.enabled] < 0.5:
        return
    lc = st[S.last_cmd]
    if lc == lc and t < lc:
        return  # older than the current command
    st[S.target0], st[S.target1], st[S.target2] = fx, fy, fz
    st[S.last_cmd] = t
    st[S.tripped] = 0.0


@nb.njit(nogil=True, cache=True)
def _fault(st, cnt, count=True):
    """A non-finite input: zero at once, the watchdog stays tripped until a valid command
    (``count``: counted here; a fault Python reports is counted there)."""
    for i in range(3):
        st[S.target0 + i] = 0.0
        st[S.out0 + i] = 0.0
    _drop_fade(st)
    st[S.last_cmd] = np.nan
    if count:
        cnt[CNT.rejected_nonfinite] += 1


@nb.njit(nogil=True, cache=True)
def _safety_output(cfg, st, cnt, now):
    """The safety rules' output: the force to apply now (device frame)."""
    if st[S.enabled] < 0.5:
        return 0.0, 0.0, 0.0
    last = st[S.last_out]
    if last != last:
        last = now
    gap = now - last
    dt = min(max(gap, 0.0), cfg[CFG.max_dt])
    st[S.last_out] = now
    lc = st[S.last_cmd]
    age = np.inf if lc != lc else now - lc
    if age > cfg[CFG.watchdog]:
        if st[S.tripped] < 0.5 and lc == lc:
            cnt[CNT.watchdog_trips] += 1
            if st[S.target0] != 0.0 or st[S.target1] != 0.0 or st[S.target2] != 0.0:
                cnt[CNT.watchdog_trips_in_contact] += 1
        st[S.tripped] = 1.0
        st[S.target0] = st[S.target1] = st[S.target2] = 0.0
        if gap > cfg[CFG.watchdog]:
            st[S.out0] = st[S.out1] = st[S.out2] = 0.0
    tx, ty, tz = st[S.target0], st[S.target1], st[S.target2]
    tn = np.sqrt(tx * tx + ty * ty + tz * tz)
    mf = cfg[CFG.max_force]
    if tn > mf:
        cnt[CNT.clamped] += 1
        s = mf / tn
        tx, ty, tz = tx * s, ty * s, tz * s
    ox, oy, oz = st[S.out0], st[S.out1], st[S.out2]
    dx, dy, dz = tx - ox, ty - oy, tz - oz
    dn = np.sqrt(dx * dx + dy * dy + dz * dz)
    step = cfg[CFG.max_force_rate] * dt
    if dn > step:
        s = step / dn
        dx, dy, dz = dx * s, dy * s, dz * s
    ox, oy, oz = ox + dx, oy + dy, oz + dz
    on = np.sqrt(ox * ox + oy * oy + oz * oz)
    if on > mf:
        s = mf / on
        ox, oy, oz = ox * s, oy * s, oz * s
    if not np.isfinite(ox + oy + oz):
        ox = oy = oz = 0.0
    st[S.out0], st[S.out1], st[S.out2] = ox, oy, oz
    return ox, oy, oz


@nb.njit(nogil=True, cache=True)
def _take(buf, scratch, seen):
    """Seqlock read of ``buf`` into ``scratch``: True when a new, consistent copy was taken
    (its sequence number differs from ``seen`` and did not change during the copy)."""
    s1 = buf[0]
    if s1 == seen or s1 % 2.0 != 0.0:
        return False
    _memcpy(scratch.ctypes.data, buf.ctypes.data, np.int64(buf.size * 8))
    s2 = buf[0]
    return s2 == s1 and scratch[0] == s1


@nb.njit(nogil=True, cache=True)
def _render(cfg, st, cnt, qx, qy, qz, now, period):
    """The local model's force (tissue frame) at the tissue position q, or NaN (nothing to offer:
    expired / no model); sets the status."""
    if st[S.m_valid] < 0.5:
        cnt[CNT.none] += 1
        st[S.status] = NONE
        return np.nan, np.nan, np.nan
    age = now - st[S.m_t0]
    ex, ey, ez = qx - st[S.m_p0], qy - st[S.m_p1], qz - st[S.m_p2]
    held = age > cfg[CFG.validity_time]
    if held and age > cfg[CFG.hold_time]:
        cnt[CNT.expired] += 1
        st[S.status] = EXPIRED
        return np.nan, np.nan, np.nan
    depth0 = st[S.m_depth0]
    depth = depth0 + st[S.m_g0] * ex + st[S.m_g1] * ey + st[S.m_g2] * ez
    if st[S.m_contact] < 0.5 or depth <= 0.0:
        cnt[CNT.free] += 1
        st[S.status] = FREE
        return 0.0, 0.0, 0.0
    if depth0 == 0.0 and across_beyond(st[S.m_g0], st[S.m_g1], st[S.m_g2], ex, ey, ez,
                                       cfg[CFG.approach_radius]):
        cnt[CNT.free] += 1   # an approach plane, away from its point (local_model's doc)
        st[S.status] = FREE
        return 0.0, 0.0, 0.0
    rh = cfg[CFG.hold_radius]
    if held and ex * ex + ey * ey + ez * ez > rh * rh:
        # held, and the probe gone from where it was made: expired while it is that far (a
        # model that says free renders zero above, counted as free, as when it is valid)
        cnt[CNT.expired] += 1
        st[S.status] = EXPIRED
        return np.nan, np.nan, np.nan
    r = cfg[CFG.validity_radius]
    if ex * ex + ey * ey + ez * ez > r * r:  # depth followed, the offset across held (module doc)
        cnt[CNT.beyond] += 1
        ex, ey, ez = hold_offset(st[S.m_g0], st[S.m_g1], st[S.m_g2], ex, ey, ez, r)
    if held:  # older than its validity, inside the hold time and the radius: still the tissue
        cnt[CNT.held] += 1
    if age <= cfg[CFG.fresh_age]:
        cnt[CNT.fresh] += 1
        st[S.status] = FRESH
    else:
        cnt[CNT.extrapolated] += 1
        st[S.status] = EXTRAPOLATED
    if depth0 == 0.0:
        cnt[CNT.approach] += 1
    # passivity: the stiffness the device renders is limited by the measured period (module doc)
    s = 1.0
    kdev = st[S.m_knorm] * cfg[CFG.force_scale] * cfg[CFG.scale]
    if kdev > 0.0 and period > 0.0:
        kmax = 2.0 * cfg[CFG.damping] / period
        if kdev > kmax:
            s = kmax / kdev
            cnt[CNT.passivity_limited] += 1
    # a held model keeps the skew part only where K has no rotating mode (local_model.rotating_mode)
    skew = 0.0 if held and st[S.m_hold_skew] < 0.5 else s
    f = np.zeros(3)
    _add_linear(st, f, 1.0, s, skew, ex, ey, ez)
    if st[S.m_zero] > 0.5 and depth < depth0:
        sx = ex - depth * st[S.m_d0]
        sy = ey - depth * st[S.m_d1]
        sz = ez - depth * st[S.m_d2]
        w = (1.0 - depth / depth0) ** 2
        _add_linear(st, f, -w, s, skew, sx, sy, sz)
    return f[0], f[1], f[2]


@nb.njit(nogil=True, cache=True)
def _take_model(st, scratch):
    """The model in ``scratch`` (a seqlock copy, all finite) becomes the current one (the
    state's ``m_*`` members are the model buffer's fields in its order: :data:`S`)."""
    for i in range(MODEL_LEN - 1):
        st[_M0 + i] = scratch[1 + i]


@nb.njit(nogil=True, cache=True)
def _drop_fade(st):
    """No step left to fade (:func:`_render_blended`): a release, a fault, a reset."""
    st[S.bl0] = st[S.bl1] = st[S.bl2] = st[S.bl_tau] = 0.0


@nb.njit(nogil=True, cache=True)
def _render_blended(cfg, st, cnt, scratch, switched, qx, qy, qz, now, period, gap):
    """:func:`_render`, a new model (``switched``: in ``scratch``) taken on the way, with the
    step between the two models faded out (module doc, 3.): where the old model and the new
    both press on the probe and differ there by more than :data:`BLEND_DEADBAND`, the force
    at this tick is the old one's but that much, and the rest of the difference is ramped out
    over tau, the old model's age at the switch (at most ``cfg[blend_time]``). A model late by
    A seconds brings the change of A seconds at once; ramped out over about A, the force
    changes about as fast as it would have had the models come on time, and a model a tick old
    is taken within a tick or two. Each tick the difference shrinks by exp(-T / tau) and tau
    by the same factor: a ramp to zero over tau, in effect, ending in a tail of a few ticks. A
    switch while a fade runs adds its own difference and keeps the longer of the two times
    left. Only the models' disagreement is faded, never the force's change with the probe's
    position (the old model is rendered at this tick's position), and never a release: a
    model that says free, an expired one or none renders zero (or NaN) at once and drops the
    fade, as a fault or a reset of the safety layer does. A force that is not finite is
    returned unfaded, for the caller's fault path."""
    cap = cfg[CFG.blend_time]
    ox = oy = oz = np.nan
    age = 0.0
    if switched:
        if cap > 0.0:   # the old model's force here: its status and counts are not this tick's
            age = now - st[S.m_t0]
            ox, oy, oz = _render(cfg, st, np.zeros_like(cnt), qx, qy, qz, now, period)
            if (st[S.status] != FRESH and st[S.status] != EXTRAPOLATED) or \
                    not np.isfinite(ox + oy + oz):
                ox = np.nan
        _take_model(st, scratch)
    fx, fy, fz = _render(cfg, st, cnt, qx, qy, qz, now, period)
    if cap <= 0.0 or not np.isfinite(fx + fy + fz) or \
            (st[S.status] != FRESH and st[S.status] != EXTRAPOLATED):
        _drop_fade(st)
        return fx, fy, fz
    tau = st[S.bl_tau]
    decay = np.exp(-max(gap, 0.0) / tau) if tau > 0.0 else 0.0
    st[S.bl0] *= decay
    st[S.bl1] *= decay
    st[S.bl2] *= decay
    st[S.bl_tau] = tau * decay
    if ox == ox:   # the step beyond BLEND_DEADBAND is faded, the rest taken at once
        dx, dy, dz = ox - fx, oy - fy, oz - fz
        dn = np.sqrt(dx * dx + dy * dy + dz * dz)
        if dn > BLEND_DEADBAND:
            c = 1.0 - BLEND_DEADBAND / dn
            st[S.bl0] += c * dx
            st[S.bl1] += c * dy
            st[S.bl2] += c * dz
            st[S.bl_tau] = max(st[S.bl_tau], min(max(age, 0.0), cap))
    return fx + st[S.bl0], fy + st[S.bl1], fz + st[S.bl2]


@nb.njit(nogil=True, cache=True)
def _add_linear(st, f, c, s, skew, ex, ey, ez):
    """f += c (F0 + s S e + skew w x e): the model's linear field at offset e, its symmetric
    stiffness S scaled by s, its skew part by skew."""
    k = S.m_k0
    w0, w1, w2 = st[S.m_w0], st[S.m_w1], st[S.m_w2]
    cx = w1 * ez - w2 * ey
    cy = w2 * ex - w0 * ez
    cz = w0 * ey - w1 * ex
    for a in range(3):
        lin = (st[S.m_f0 + a] + s * (st[k + 3 * a] * ex + st[k + 3 * a + 1] * ey
                                     + st[k + 3 * a + 2] * ez)
               + skew * (cx if a == 0 else (cy if a == 1 else cz)))
        f[a] += c * lin


@nb.njit(nogil=True, cache=True)
def _passivity_period(cfg, st, gap):
    """The period the passivity bound uses [s]: sum(T^2) / sum(T) over the periods T of the last
    ``cfg[passivity_window]`` (exponentially weighted; each T capped at the watchdog time, past
    which the force was ramped down). At a steady hand speed v a zero-order hold leaks
    K v^2 T^2 / 2 per period and the device's damping takes b v^2 T, so the window is passive
    when K <= 2 b sum(T) / sum(T^2). One late tick among nominal ones (a bounded leak, once)
    lowers the bound less the longer the window (with a model at the guard's stiffness a
    7.5 ms gap scales it to ~0.3 at 20 ms, ~0.5 at 50 ms), for about the window's time; a
    loop that keeps ticking late meets the per-period bound once the window has filled. The
    sums start as if the loop had run at its nominal period."""
    t = min(gap, cfg[CFG.watchdog])
    w = cfg[CFG.passivity_window]
    if st[S.pt1] <= 0.0:
        st[S.pt1] = w
        st[S.pt2] = w * cfg[CFG.period]
    lam = np.exp(-t / w)
    st[S.pt1] = lam * st[S.pt1] + t
    st[S.pt2] = lam * st[S.pt2] + t * t
    return st[S.pt2] / st[S.pt1]


@nb.njit(nogil=True, cache=True)
def tick(now, cfg, st, cnt, script, buf, scratch, stamp_ns):
    """One servo tick at monotonic time ``now`` [s] (see the module docstring); ``stamp_ns``: the
    wall-clock stamp the published pose carries. Returns the applied force's magnitude [N]."""
    n, qx, qy, qz, b0, b1 = _compute(now, cfg, st, cnt, script, buf, scratch)
    _publish(now, st, cnt, buf, scratch, stamp_ns, qx, qy, qz, b0, b1)
    return n


@nb.njit(nogil=True, cache=True)
def _compute(now, cfg, st, cnt, script, buf, scratch):
    """Steps 1-5 of a tick and its timing counters, on ``st`` and ``cnt`` only (the shared
    buffers ``buf.out`` and ``buf.trace`` are :func:`_publish`'s): a worker may run it on copies
    and throw the result away (:func:`run`). Returns the applied force's magnitude [N], the
    tissue position (with the clutch) and the buttons."""
    cmd, model, ctl = buf.cmd, buf.model, buf.ctl
    # inputs first: enable / disable, faults, the newest command and model
    if ctl[CTL.enable_gen] != st[S.enable_seen]:
        st[S.enable_seen] = ctl[CTL.enable_gen]
        _safety_reset(st, now, ctl[CTL.enabled] != 0)
    elif ctl[CTL.enabled] == 0 and st[S.enabled] > 0.5:
        _safety_reset(st, now, False)
    if ctl[CTL.fault] != st[S.fault_seen]:
        st[S.fault_seen] = ctl[CTL.fault]
        st[S.m_valid] = 0.0
        _drop_fade(st)
        if st[S.enabled] > 0.5:
            _fault(st, cnt, False)
    switched = False   # a new model in scratch, taken at the render (3.)
    if _take(model, scratch, st[S.model_seen]):
        st[S.model_seen] = scratch[0]
        ok = True
        for i in range(1, MODEL_LEN):
            if not np.isfinite(scratch[i]):
                ok = False
        if ok:
            switched = True
        else:  # never render a non-finite model: zero at once
            st[S.m_valid] = 0.0
            if st[S.enabled] > 0.5:
                _fault(st, cnt)
    gap = now - st[S.t_prev] if st[S.t_prev] == st[S.t_prev] else cfg[CFG.period]
    period = _passivity_period(cfg, st, gap)
    # 1. device
    b0, b1 = _device_read(cfg, st, script, buf, now)
    sc, fs = cfg[CFG.scale], cfg[CFG.force_scale]
    mx = cfg[CFG.ox] + sc * st[S.x0]
    my = cfg[CFG.oy] + sc * st[S.x1]
    mz = cfg[CFG.oz] + sc * st[S.x2]
    # 2. clutch / mark
    qx, qy, qz = _clutch(st, cnt, b0, b1, mx, my, mz)
    # 3. render (device frame)
    if cfg[CFG.mode] > 0.5:
        fx, fy, fz = _render_blended(cfg, st, cnt, scratch, switched, qx, qy, qz, now, period,
                                     gap)
        if fx == fx:
            if not np.isfinite(fx + fy + fz):
                _fault(st, cnt)
            else:
                g = _gain(cfg, st, fx != 0.0 or fy != 0.0 or fz != 0.0, now)
                _command(st, g * fs * fx, g * fs * fy, g * fs * fz, now)
    else:
        if switched:
            _take_model(st, scratch)
        st[S.status] = -1.0
        if _take(cmd, scratch, st[S.cmd_seen]):
            st[S.cmd_seen] = scratch[0]
            fx, fy, fz, t = scratch[CMD.f0], scratch[CMD.f1], scratch[CMD.f2], scratch[CMD.t]
            if np.isfinite(fx + fy + fz + t):
                g = _gain(cfg, st, fx != 0.0 or fy != 0.0 or fz != 0.0, now)
                _command(st, g * fx, g * fy, g * fz, t)
            elif st[S.enabled] > 0.5:
                _fault(st, cnt)
    # 4. passivity observer / controller (optional): energy out of the rendered port
    ox, oy, oz = _safety_output(cfg, st, cnt, now)
    if cfg[CFG.observer] > 0.5 and st[S.enabled] > 0.5:
        vx, vy, vz = st[S.v0], st[S.v1], st[S.v2]
        e = st[S.energy] - (st[S.f0] * vx + st[S.f1] * vy + st[S.f2] * vz) * gap
        vv = vx * vx + vy * vy + vz * vz
        if e < 0.0 and vv > 1e-12 and gap > 0.0:
            alpha = min(-e / (gap * vv), 2.0 * cfg[CFG.damping] + cfg[CFG.hand_c])
            ox -= alpha * vx
            oy -= alpha * vy
            oz -= alpha * vz
            e += alpha * vv * gap
            cnt[CNT.observer_active] += 1
        st[S.energy] = e
    # 5. device, counters
    _device_write(cfg, st, ox, oy, oz)
    fx, fy, fz = st[S.f0], st[S.f1], st[S.f2]
    n = np.sqrt(fx * fx + fy * fy + fz * fz)
    if n * 1e6 > cnt[CNT.max_force_un]:
        cnt[CNT.max_force_un] = int(n * 1e6)
    # timing counters
    period = cfg[CFG.period]
    if st[S.t_prev] == st[S.t_prev]:
        cnt[CNT.periods_lost] += periods_lost_in(gap, period)
        g_ns = int(gap * 1e9)
        if g_ns > cnt[CNT.max_gap_ns]:
            cnt[CNT.max_gap_ns] = g_ns
        if gap > cfg[CFG.watchdog]:   # a gap the hand felt as a stop (LoopStats.long_gaps)
            cnt[CNT.long_gaps] += 1
    else:
        cnt[CNT.t_first_ns] = int(now * 1e9)
    cnt[CNT.t_last_ns] = int(now * 1e9)
    st[S.t_prev] = now
    cnt[CNT.ticks] += 1
    return n, qx, qy, qz, b0, b1


@nb.njit(nogil=True, cache=True)
def _publish(now, st, cnt, buf, scratch, stamp_ns, qx, qy, qz, b0, b1):
    """Step 6 of a tick: its trace row and the published state (a seqlock) from ``st``."""
    out, trace = buf.out, buf.trace
    fx, fy, fz = st[S.f0], st[S.f1], st[S.f2]
    w = cnt[CNT.trace_w]
    if trace.shape[0] > 0:
        row = w % trace.shape[0]
        trace[row, 0] = now
        trace[row, 1], trace[row, 2], trace[row, 3] = st[S.x0], st[S.x1], st[S.x2]
        trace[row, 4], trace[row, 5], trace[row, 6] = fx, fy, fz
        trace[row, 7] = st[S.status] if st[S.enabled] > 0.5 else DISABLED
    seq = out[OUT.seq]
    scratch[0] = seq + 1.0
    scratch[OUT.t] = now
    for i in range(3):
        scratch[OUT.p0 + i] = st[S.x0 + i]
        scratch[OUT.v0 + i] = st[S.v0 + i]
        scratch[OUT.f0 + i] = st[S.f0 + i]
    scratch[OUT.q0], scratch[OUT.q1], scratch[OUT.q2] = qx, qy, qz
    scratch[OUT.status] = st[S.status]
    scratch[OUT.held] = st[S.held]
    scratch[OUT.b0], scratch[OUT.b1], scratch[OUT.b2], scratch[OUT.b3] = b0, b1, 0.0, 0.0
    scratch[OUT.stamp_hi] = float(stamp_ns // 1000000000)
    scratch[OUT.stamp_lo] = float(stamp_ns % 1000000000)
    out[OUT.seq] = seq + 1.0  # odd: being written
    _memcpy(out.ctypes.data + 8, scratch.ctypes.data + 8, np.int64((OUT_LEN - 1) * 8))
    out[OUT.seq] = seq + 2.0
    cnt[CNT.trace_w] = w + 1


#: counters a worker's tick changes that are not sums: the largest value wins, or the newest
_CNT_MAX = (CNT.max_gap_ns, CNT.max_force_un)
_CNT_SET = (CNT.t_first_ns, CNT.t_last_ns)


@nb.njit(nogil=True, cache=True)
def _claim(now_ns, period_ns, ctl, st, cnt, st_w, cnt_w, base):
    """Under the workers' mutex: claim the due tick. Returns (claimed, deadline, generation):
    when claimed, ``st_w`` and ``cnt_w`` hold copies of the state and counters (``base`` the
    counters as copied) for :func:`_compute`, and ``deadline`` is the period claimed; else
    ``deadline`` is when to look again. A tick claimed by another worker more than a period ago
    and not committed (that worker is not running: preempted mid-tick) is taken over."""
    deadline = cnt[CNT.deadline_ns]
    if deadline == 0:  # the first tick: the schedule starts now
        deadline = now_ns
    if now_ns < deadline or ctl[CTL.stop] != 0:
        return False, deadline, 0
    if cnt[CNT.claim_ns] == deadline:
        if now_ns - cnt[CNT.claim_at_ns] <= period_ns:
            return False, deadline + period_ns, 0  # being run: look again a period on
        cnt[CNT.taken_over] += 1
    if now_ns - deadline > period_ns:
        cnt[CNT.deadline_misses] += 1
        deadline = now_ns
    cnt[CNT.deadline_ns] = deadline  # also the first: the other worker finds it claimed
    cnt[CNT.claim_ns] = deadline
    cnt[CNT.claim_at_ns] = now_ns
    st_w[:] = st
    cnt_w[:] = cnt
    base[:] = cnt
    return True, deadline, cnt[CNT.gen]


@nb.njit(nogil=True, cache=True)
def _commit(gen, deadline, period_ns, st, cnt, st_w, cnt_w, base):
    """Under the workers' mutex: make a claimed tick's state and counters (computed on the
    copies) the loop's, unless another worker committed since the claim (then nothing is
    written: that worker took the tick over). Returns whether it was committed."""
    if cnt[CNT.gen] != gen:
        return False
    st[:] = st_w
    for i in range(cnt.shape[0]):
        d = cnt_w[i] - base[i]
        if d != 0:
            if i == _CNT_MAX[0] or i == _CNT_MAX[1]:
                # a window reset since the claim stays reset but for this tick's own value
                cnt[i] = max(cnt[i], cnt_w[i])
            elif i == _CNT_SET[0] or i == _CNT_SET[1]:
                cnt[i] = cnt_w[i]
            else:
                cnt[i] += d
    cnt[CNT.gen] = gen + 1
    cnt[CNT.claim_ns] = 0
    cnt[CNT.deadline_ns] = deadline + period_ns
    return True


@nb.njit(nogil=True, cache=True)
def run(cfg, st, cnt, script, buf, scratch, ts, lock):
    """The servo loop of one worker: a tick every ``period`` to absolute deadlines until
    ``ctl[stop]``. Several workers (threads of one process, each calling this with its own
    ``ts`` and the same arrays and ``lock``) serve ONE schedule: each sleeps to the next deadline;
    the first to wake claims the tick (:func:`_claim`, under the lock), computes it on its own
    copies of the state and counters with the lock let go (:func:`_compute`), then commits it
    and publishes it (:func:`_commit`, :func:`_publish`, under the lock); the others find it
    not due or claimed and sleep to the next one. Under the normal scheduler one thread is
    sometimes not run for milliseconds after it wakes (a busy core, a long kernel path); two
    workers pinned to different cores are rarely both held. A worker preempted in the middle of its tick holds no lock:
    a period later the other takes the tick over from the last committed state, and the late
    one's result is dropped (``taken_over``). A tick more than one period late is a deadline
    miss and the schedule re-synchronises (the periods lost are counted by :func:`_compute`).
    Each worker leaves the device at zero force on its way out (under the lock, so after any
    commit in progress); the last one also clears the schedule. Returns the number of ticks."""
    period_ns = int(cfg[CFG.period] * 1e9 + 0.5)
    ctl = buf.ctl
    m = lock.ctypes.data
    _mutex_lock(m)
    cnt[CNT.running] += 1
    _mutex_unlock(m)
    st_w, cnt_w, base, scr = np.empty_like(st), np.empty_like(cnt), np.empty_like(cnt), \
        np.empty_like(scratch)
    mine = np.int64(0)
    while ctl[CTL.stop] == 0:
        claimed, deadline, gen = False, np.int64(0), np.int64(0)
        now_ns = np.int64(0)
        if _mutex_trylock(m) == 0:
            _clock_gettime(CLOCK_MONOTONIC, ts.ctypes.data)
            now_ns = ts[0] * 1000000000 + ts[1]
            claimed, deadline, gen = _claim(now_ns, period_ns, ctl, st, cnt, st_w, cnt_w, base)
            _mutex_unlock(m)
            mine = deadline
        else:  # another worker is claiming or committing: this period is served
            mine = max(mine, cnt[CNT.deadline_ns]) + period_ns
        if claimed:
            _clock_gettime(CLOCK_REALTIME, ts.ctypes.data)
            stamp = ts[0] * 1000000000 + ts[1]
            _, qx, qy, qz, b0, b1 = _compute(now_ns * 1e-9, cfg, st_w, cnt_w, script, buf, scr)
            _mutex_lock(m)
            if _commit(gen, deadline, period_ns, st, cnt, st_w, cnt_w, base):
                _publish(now_ns * 1e-9, st, cnt, buf, scr, stamp, qx, qy, qz, b0, b1)
            mine = cnt[CNT.deadline_ns]
            _mutex_unlock(m)
        ts[0] = mine // 1000000000
        ts[1] = mine % 1000000000
        _clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, ts.ctypes.data, 0)
    _mutex_lock(m)
    _safety_reset(st, 0.0, False)
    _device_write(cfg, st, 0.0, 0.0, 0.0)
    cnt[CNT.running] -= 1
    if cnt[CNT.running] == 0:
        cnt[CNT.deadline_ns] = 0
        cnt[CNT.claim_ns] = 0
    _mutex_unlock(m)
    return cnt[CNT.ticks]
