"""The servo loop without the interpreter lock: the compiled tick on its own workers (no ROS).

:class:`NativeServoLoop` runs :func:`haptic_anfis.device.native_tick.run` on its tick workers
(two threads by default, each pinned to its own core, serving one schedule: the first to wake runs
the tick), in a servo process of its own or in this one: the compiled loop releases the GIL once
and keeps it released until it is told to stop, so nothing else in the process (executors,
recorder, garbage collector, a view) can delay a tick. A second,
ordinary Python thread, the *bridge*, does what needs the interpreter, at whatever pace it gets:
it reads the newest published tick (a seqlock), hands it to ``on_state`` (the driver publishes
the pose and takes the newest command / local model from its readers), and drains the tick
trace. Commands and models go the other way through :class:`~.tick_views.NativeSafety` and
:class:`~.tick_views.NativeRenderer`, which write the loop's input buffers
(:mod:`.tick_views`).

A stalled bridge (or a frozen process, short of SIGSTOP) does not stop the ticks: the last model
is rendered until it expires (``model_validity_time`` from its pose) and the watchdog then ramps
the force to zero inside the compiled loop.

The real Falcon (``device_factory``): its USB library is Python, so the device's I/O runs in
the servo process around the same compiled tick (:mod:`.device_process`); that process holds
nothing but the device, so no executor, recorder or frozen node delays it, and the tick's
watchdog zeroes the force whatever the node does (see docs/servo_loop.md).
"""
from __future__ import annotations

import dataclasses
import gc
import math
import os
import signal
import threading
import time
from typing import Callable

import numpy as np

from . import device_process as dp
from . import native_tick as nt
from ..realtime.scheduling import name_thread, schedule_servo_thread, worker_cpus
from ..realtime.shm import SharedArrays, die_with_parent
from .falcon import HandParams, WorkspaceMapping
from .local_model import (APPROACH_RADIUS, FALCON_MAX_STIFFNESS, HOLD_RADIUS, MODEL_BLEND_TIME,
                          PASSIVITY_WINDOW, tissue_stiffness_limit)
from .stats import LoopStats
from .tick_views import (NativeClutch, NativeLoopStats, NativeRenderer, NativeSafety,
                         NativeState, seq_read, seq_write)
from .trace import TickTrace

__all__ = ['NativeServoLoop', 'script_arrays', 'FALCON_DAMPING']

#: device damping b [N s/m] the passivity bound assumes: with CHAI3D's Falcon stiffness
#: (3000 N/m) at T = 1 ms, b > K T / 2 asks 1.5 N s/m; the bound then only bites when a tick is
#: late (K <= 2 b / T).
FALCON_DAMPING = 1.5


def script_arrays(script) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool, bool]:
    """(times (n,), points (n, 3) tissue frame, buttons (n - 1, 2) or (0, 2), loop, held) of a
    :class:`~.palpation.PalpationScript` or a :class:`~.start_gate.HeldScript` around one."""
    held = bool(getattr(script, 'held', False))
    inner = getattr(script, 'script', script)
    times = np.ascontiguousarray(inner.times, dtype=np.float64)
    points = np.ascontiguousarray(inner.points, dtype=np.float64).reshape(-1, 3)
    bs = inner.button_states
    buttons = (np.zeros((0, 2), dtype=np.int64) if bs is None or not np.any(bs)
               else np.ascontiguousarray(bs, dtype=np.int64).reshape(-1, 2))
    return times, points, buttons, bool(inner.loop), held


def _check_number(name: str, value, unit: str, zero: bool = False) -> None:
    """Raise ValueError naming ``name`` unless ``value`` is a finite number (not a bool) above 0,
    or at least 0 with ``zero``; ``unit``: the unit the message names."""
    ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
          and math.isfinite(value) and (value >= 0 if zero else value > 0))
    if not ok:
        raise ValueError(f'{name}: expected a finite number {">=" if zero else ">"} 0 {unit}, '
                         f'got {value!r}')


class NativeServoLoop:
    """The simulated Falcon's servo loop, compiled and GIL-free (module docstring).

    Args:
        script: the hand's :class:`~.palpation.PalpationScript` (or a
            :class:`~.start_gate.HeldScript` around one: held until :meth:`release`).
        mapping, hand: as :class:`~.falcon.SimulatedFalcon`'s.
        rate: servo rate [Hz].
        max_force, max_force_rate, watchdog_timeout, frame_id: the safety layer's.
        mode: ``'local_model'`` or ``'zoh'``.
        max_stiffness: device-frame stiffness bound [N/m]; validity_time [s], validity_radius [m],
            approach_radius [m]: the local model's (:mod:`.local_model`'s rules).
        damping: device damping b [N s/m] of the passivity bound K <= 2 b / T.
        observer: run the passivity observer / controller (Hannaford & Ryu 2002).
        hold_time: a model older than ``validity_time`` but not than this [s] is still rendered
            (``held`` ticks; <= validity_time: off) while the probe is within ``hold_radius``
            [m] of its p0 (:data:`~.local_model.HOLD_RADIUS`; further: expired for those
            ticks); then it expires.
        blend_time: the step between two successive models is ramped out over the old model's
            age, at most this [s] (:data:`~.local_model.MODEL_BLEND_TIME`; 0: off, the new
            model at once).
        passivity_window: time constant [s] of the tick periods the passivity bound weighs
            (``T = sum(T_k^2) / sum(T_k)``, exponentially weighted;
            :data:`~.local_model.PASSIVITY_WINDOW`).
        on_state: ``on_state(state: NativeState, force, now)`` on the bridge thread for the newest
            tick (force: device frame).
        trace: a :class:`~.trace.TickTrace` the bridge fills (tissue frame), or None.
        priority: SCHED_FIFO priority of the tick thread (0: the normal scheduler, with a short
            time slice requested); the bridge gets ``priority - 10`` (at least 1) when > 0.
        ring: trace ring rows in the loop (the bridge must drain it within ``ring`` ticks).
        process: run the compiled loop in a child process of its own session (``fork`` +
            ``setsid``: its own scheduler autogroup, so the parent's busy threads do not share
            its CPU time), on shared memory; else on threads of this process.
        workers: threads that serve the one tick schedule (:func:`~.native_tick.run`), each
            pinned to its own core (:func:`worker_cpus`): the first to wake runs the tick, so a
            core held busy for milliseconds costs no tick. At most the cores this process
            may use; 1 is a single servo thread.
        device_factory: a real device instead of the simulated handle (``script`` is then
            None): called IN the servo process (implies ``process``) to build the
            :class:`~.falcon.Device` (e.g. a :class:`~.falcon_usb.FalconUSB`) that
            :func:`~.device_process.run_device_loop` reads and writes around every tick.
            :attr:`device` shows its counters.
        open_timeout: seconds :meth:`start` waits for the device to open (firmware, homing).
        open_error: the exception type :meth:`start` raises, with the servo process's one-line
            message, when the device could not be opened.
    """

    def __init__(self, script, mapping: WorkspaceMapping = WorkspaceMapping(),
                 hand: HandParams = HandParams(), rate: float = 1000.0, max_force: float = 8.9,
                 max_force_rate: float = 1000.0, watchdog_timeout: float = 0.010,
                 frame_id: str = 'tissue', mode: str = 'local_model',
                 max_stiffness: float = FALCON_MAX_STIFFNESS, validity_time: float = 0.05,
                 validity_radius: float = 0.005, damping: float = FALCON_DAMPING,
                 observer: bool = False, hold_time: float = 0.0,
                 on_state: Callable[[NativeState, tuple, float], None] | None = None,
                 trace: TickTrace | None = None, priority: int = 0, ring: int = 1 << 16,
                 half_extent: float = 0.05, device_max_force: float | None = None,
                 process: bool = False, device_factory: Callable[[], object] | None = None,
                 open_timeout: float = 120.0, open_error: type[Exception] = OSError,
                 workers: int = 2, approach_radius: float = APPROACH_RADIUS,
                 hold_radius: float = HOLD_RADIUS,
                 blend_time: float = MODEL_BLEND_TIME,
                 passivity_window: float = PASSIVITY_WINDOW) -> None:
        if not rate > 0:
            raise ValueError(f'rate: expected > 0 Hz, got {rate!r}')
        if not 0 <= priority <= 99:
            raise ValueError(f'priority: expected 0 (normal scheduling) to 99, got {priority!r}')
        if mode not in ('zoh', 'local_model'):
            raise ValueError(f"mode: expected 'zoh' or 'local_model', got {mode!r}")
        _check_number('damping', damping, 'N s/m')
        _check_number('hold_radius', hold_radius, 'm')
        _check_number('blend_time', blend_time, 's', zero=True)
        _check_number('passivity_window', passivity_window, 's')
        if not (isinstance(workers, int) and 1 <= workers <= 8):
            raise ValueError(f'workers: expected an integer from 1 to 8, got {workers!r}')
        self.period = 1.0 / rate
        self.priority = int(priority)
        self.mapping, self.on_state, self.trace = mapping, on_state, trace
        self.device_factory = device_factory
        self.open_timeout, self.open_error = float(open_timeout), open_error
        if device_factory is not None:  # no script: a still handle at the centre, never read
            self.times, points, self.buttons, loop, held = (
                np.zeros(1), np.zeros((1, 3)), np.zeros((0, 2), dtype=np.int64), False, False)
            points[0] = mapping.offset
        else:
            self.times, points, self.buttons, loop, held = script_arrays(script)
        self.points = points
        self._script = script
        self.process = bool(process) or device_factory is not None
        self._mem = SharedArrays() if self.process else None
        zeros = self._mem.zeros if self.process else np.zeros
        self.hand = zeros(nt.HAND_LEN)
        C = nt.CFG
        cfg = zeros(nt.CFG_LEN)   # shared with a servo process: set_force_scale reaches it
        cfg[C.period] = self.period
        cfg[C.max_force], cfg[C.max_force_rate] = max_force, max_force_rate
        cfg[C.watchdog], cfg[C.max_dt] = watchdog_timeout, 0.005
        cfg[C.validity_time], cfg[C.validity_radius] = validity_time, validity_radius
        cfg[C.approach_radius] = approach_radius
        cfg[C.fresh_age] = 1.5 * self.period
        cfg[C.max_stiffness] = tissue_stiffness_limit(max_stiffness, mapping.force_scale,
                                                      mapping.scale)
        cfg[C.scale], cfg[C.force_scale] = mapping.scale, mapping.force_scale
        cfg[C.ox], cfg[C.oy], cfg[C.oz] = mapping.offset
        cfg[C.hand_m], cfg[C.hand_k], cfg[C.hand_c] = hand.mass, hand.stiffness, hand.damping
        cfg[C.half], cfg[C.dt_max], cfg[C.max_catch_up] = half_extent, 0.001, 0.05
        cfg[C.ramp] = 0.005
        cfg[C.damping] = damping
        cfg[C.mode] = 1.0 if mode == 'local_model' else 0.0
        cfg[C.observer] = 1.0 if observer else 0.0
        cfg[C.loop] = 1.0 if loop else 0.0
        cfg[C.dev_max_force] = max_force if device_max_force is None else device_max_force
        cfg[C.hold_time] = max(float(hold_time), validity_time)
        cfg[C.hold_radius] = hold_radius
        cfg[C.blend_time] = blend_time
        cfg[C.passivity_window] = passivity_window
        cfg[C.device] = 1.0 if device_factory is not None else 0.0
        self.cfg = cfg
        #: the real device's status and counters (:data:`~.device_process.DEV`), its message
        self.devst = zeros(dp.DEV_LEN, dtype=np.int64)
        self.devmsg = zeros(dp.MESSAGE_BYTES, dtype=np.uint8)
        #: the servo process's own words for how its servo thread is scheduled (written there)
        self.schedmsg = zeros(dp.MESSAGE_BYTES, dtype=np.uint8)
        self.device = dp.ProcessDevice(self.devst) if device_factory is not None else None
        #: called on the bridge thread when the real device is lost / back (a message)
        self.on_disconnect: Callable[[str], None] | None = None
        self.on_reconnect: Callable[[str], None] | None = None
        self.st = zeros(nt.STATE_LEN)
        self.st[:] = nt.new_state()
        x0 = [min(max((points[0, k] - mapping.offset[k]) / mapping.scale, -half_extent),
                  half_extent) for k in range(3)]
        self.st[nt.S.x0:nt.S.x0 + 3] = x0
        self.cmd = zeros(nt.CMD_LEN)
        self.model = zeros(nt.MODEL_LEN)
        self.ctl = zeros(nt.CTL_LEN, dtype=np.int64)
        self.ctl[nt.CTL.release] = 0 if held else 1
        self.out = zeros(nt.OUT_LEN)
        self.cnt = zeros(nt.CNT_LEN, dtype=np.int64)
        self.ring = zeros((int(ring) if trace is not None else 0, nt.TRACE_COLS))
        #: the arrays the compiled loop takes, by name (the same arrays as the attributes)
        self.hand_script = nt.Script(self.times, self.points, self.buttons)
        self.buffers = nt.Buffers(self.hand, self.cmd, self.model, self.ctl, self.out, self.ring)
        self._scratch = np.zeros(nt.SCRATCH_LEN)
        self.workers = int(workers)
        self._lock = np.zeros(nt.LOCK_LEN, dtype=np.int64)  # the workers' mutex (one process)
        self._cpus = worker_cpus(self.workers)  # before any worker pins itself
        self.safety = NativeSafety(self, max_force, max_force_rate, watchdog_timeout, frame_id)
        self.renderer = NativeRenderer(self, tissue_stiffness_limit(
            max_stiffness, mapping.force_scale, mapping.scale), validity_time, validity_radius,
            1.5 * self.period, approach_radius)
        self.clutch = NativeClutch(self)
        self.stats = NativeLoopStats(self.cnt, self.period)
        self.scheduling = ''
        self.errors = 0
        self.last_error: BaseException | None = None
        self.trace_lost = 0  # trace rows overwritten before the bridge drained them
        self.bridge_gaps = LoopStats(period=self.period)  # the bridge's own pace
        self.last_out = self.out.copy()
        self.last_state: NativeState | None = None
        self.force = (0.0, 0.0, 0.0)
        self.status = -1
        self._read = 0
        self._stop = threading.Event()
        self._tick_threads: list[threading.Thread] = []
        self._pid = 0
        self._bridge: threading.Thread | None = None
        self._scheduled = threading.Event()

    # -- control --------------------------------------------------------------------------------
    def set_force_scale(self, force_scale: float, max_stiffness: float) -> WorkspaceMapping:
        """Render from the next tick with ``F_device = force_scale * F_tissue`` (a case switched
        in a running session: each case has its own scale); ``max_stiffness``: the device-frame
        stiffness bound [N/m] the tissue-frame one follows from. The safety layer's rate limit
        ramps the device force to the new scale. Returns the new mapping.

        Raises:
            ValueError: ``force_scale`` is not a finite number > 0.
        """
        m = dataclasses.replace(self.mapping, force_scale=force_scale)
        k = tissue_stiffness_limit(max_stiffness, m.force_scale, m.scale)
        self.renderer.max_stiffness = k   # the models accepted from now on
        self.cfg[nt.CFG.max_stiffness] = k
        self.cfg[nt.CFG.force_scale] = m.force_scale
        self.mapping = m
        return m

    def release(self) -> None:
        """Start the held script at the next tick (idempotent)."""
        self.ctl[nt.CTL.release] = 1

    @property
    def script(self):
        """The hand's script. Setting one (e.g. ``exam run``'s simulated trainee, a script only
        Python can play) makes the bridge play it: it writes the hand target (and its velocity)
        at its pace and the compiled tick extrapolates it for at most
        :data:`~.native_tick.HAND_EXTRAPOLATE`."""
        return self._script

    @script.setter
    def script(self, script) -> None:
        self._script = script
        self._feed_hand()
        self.ctl[nt.CTL.external] = 1

    def _feed_hand(self) -> None:
        """The external script's hand target at the bridge's time (device frame)."""
        s = self._script
        t0 = float(self.st[nt.S.t_open])  # plain floats to the script (it keeps its time)
        now = time.monotonic()
        t = (now - t0) if t0 == t0 and t0 > 0 else 0.0
        m, dt = self.mapping, 0.002
        p = m.to_device(s.target(t))
        p1 = m.to_device(s.target(t + dt))
        b = s.buttons(t) if hasattr(s, 'buttons') else (0, 0)
        v, H = [0.0] * nt.HAND_LEN, nt.HAND
        v[H.t], v[H.b0], v[H.b1] = now, float(b[0]), float(b[1])
        for k in range(3):
            v[H.x0 + k], v[H.v0 + k] = p[k], (p1[k] - p[k]) / dt
        seq_write(self.hand, v[1:])

    @property
    def held(self) -> bool:
        return bool(self.ctl[nt.CTL.release] == 0)

    def compile(self) -> None:
        """Compile (or load from numba's cache) the loop: :func:`~.native_tick.run` on copies, told
        to stop before its first tick."""
        ctl = self.ctl.copy()
        ctl[nt.CTL.stop] = 1  # run returns at once
        b = self.buffers
        copies = nt.Buffers(b.hand.copy(), b.cmd.copy(), b.model.copy(), ctl, b.out.copy(),
                            b.trace[:0].copy())
        nt.run(self.cfg, self.st.copy(), self.cnt.copy(), self.hand_script, copies,
               self._scratch.copy(), np.zeros(2, dtype=np.int64), self._lock.copy())
        if self.device_factory is not None:  # the device loop calls these from Python
            st, cnt = self.st.copy(), self.cnt.copy()
            nt.tick(0.0, self.cfg, st, cnt, self.hand_script,
                    copies._replace(trace=b.trace.copy()), self._scratch.copy(), 0)
            nt._fault(st, cnt)

    def tick(self, now: float, stamp_ns: int = 0) -> tuple[float, float, float]:
        """One compiled tick at monotonic ``now`` [s] on this loop's state, without the thread
        (tests); returns the force written to the device (device frame) [N]."""
        nt.tick(float(now), self.cfg, self.st, self.cnt, self.hand_script, self.buffers,
                self._scratch, int(stamp_ns))
        S = nt.S
        return float(self.st[S.f0]), float(self.st[S.f1]), float(self.st[S.f2])

    def start(self) -> None:
        self.compile()
        self.safety.start()
        if self.process:
            self._start_process()
        else:
            self._tick_threads = self._start_workers()
            self._scheduled.wait(1.0)
        self._bridge = threading.Thread(target=self._run_bridge, name='servo-bridge', daemon=True)
        self._bridge.start()

    def _start_process(self) -> None:
        """Fork the servo process: it only runs the compiled loop (compiled before the fork) on
        the shared arrays and exits with ``os._exit``; it dies with this process (PDEATHSIG)."""
        pid = os.fork()
        if pid == 0:  # the child: no Python threads, no ROS; only the compiled loop
            # Never collect what the parent left: a finalizer of its garbage (an rclpy node, a
            # subscription) calls into DDS, whose locks other threads of the parent may have
            # held at the fork, and the child then hangs for good (seen: the Falcon's device
            # loop, which runs Python, stopped; 1-3 forks in 20 with a leaked node).
            gc.freeze()
            code = 0
            try:
                os.setsid()  # a session of its own: its own autogroup (fair share) on Linux
                if self.device_factory is not None:
                    # a real device must be left at zero force: stop the loop, do not kill it
                    signal.signal(signal.SIGTERM, lambda *_: self.ctl.__setitem__(nt.CTL.stop, 1))
                    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C: the node stops us
                    die_with_parent(signal.SIGTERM)
                else:
                    die_with_parent(signal.SIGKILL)
                if self.device_factory is not None:
                    name_thread('servo-device')
                    # the device loop: its USB I/O
                    dp.write_message(self.schedmsg, schedule_servo_thread(self.priority))
                    code = dp.run_device_loop(
                        self.device_factory, self.cfg, self.st, self.cnt, self.hand_script,
                        self.buffers, self._scratch, self.devst, self.devmsg)
                else:
                    for th in self._start_workers(first=1):  # worker 0 is this thread
                        th.join()
            except BaseException:
                code = 1
            finally:
                os._exit(code)
        self._pid = pid
        if self.device_factory is not None:
            self._wait_open(pid)
        # how the child's servo thread is scheduled, in its own words (with rtkit's reason when
        # it refused), once it has set itself up: milliseconds, but rtkit's three D-Bus calls
        # may each take their 2 s timeout when the bus hangs
        end = time.monotonic() + 10.0
        while not (words := dp.read_message(self.schedmsg)) and time.monotonic() < end:
            time.sleep(0.01)
        self.scheduling = (f'compiled tick in servo process {pid} (own session); '
                           f'{words or "scheduling not reported"}'
                           + ('' if self.device_factory is not None else
                              f'; {self._workers_text()}'))

    def _wait_open(self, pid: int) -> None:
        """Wait for the servo process to open the device; raise ``open_error`` with its message
        when it could not (the process has exited then)."""
        end = time.monotonic() + self.open_timeout
        while self.devst[dp.DEV.state] == dp.STARTING:
            done = os.waitpid(pid, os.WNOHANG)[0]
            if done or time.monotonic() > end:
                if not done:
                    os.kill(pid, 9)
                    os.waitpid(pid, 0)
                self._pid = 0
                raise self.open_error(
                    'the servo process died while opening the device' if done else
                    f'the device did not open within {self.open_timeout:g} s')
            time.sleep(0.005)
        if self.devst[dp.DEV.state] == dp.FAILED:
            os.waitpid(pid, 0)
            self._pid = 0
            raise self.open_error(dp.read_message(self.devmsg))

    def stop(self, timeout: float = 2.0) -> None:
        self.safety.stop()
        self.ctl[nt.CTL.stop] = 1
        self._stop.set()
        for th in (*self._tick_threads, self._bridge):
            if th is not None and th is not threading.current_thread():
                th.join(timeout)
        if self._pid:
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                if os.waitpid(self._pid, os.WNOHANG)[0]:
                    self._pid = 0
                    break
                time.sleep(0.005)
            else:
                os.kill(self._pid, 9)
                os.waitpid(self._pid, 0)
                self._pid = 0
                self.st[nt.S.f0:nt.S.f0 + 3] = 0.0
        self._drain()
        self.force = (0.0, 0.0, 0.0)

    @property
    def running(self) -> bool:
        if self._pid:
            return bool(self.cnt[nt.CNT.running])
        return any(th.is_alive() for th in self._tick_threads)

    # -- threads --------------------------------------------------------------------------------
    def _start_workers(self, first: int = 0) -> list[threading.Thread]:
        """Start the tick workers ``first`` .. ``workers - 1`` as threads, each on its core; when
        ``first`` is 1 the calling thread is worker 0 and runs it before returning (the servo
        process's main thread). Returns the started threads."""
        cpus = self._cpus
        threads = [threading.Thread(target=self._run_ticks, args=(w, cpus[w]), daemon=True,
                                    name=f'servo-tick{w}') for w in range(first, len(cpus))]
        for th in threads:
            th.start()
        if first == 1:
            self._run_ticks(0, cpus[0])
        return threads

    def _workers_text(self) -> str:
        cpus = self._cpus
        return (f'{len(cpus)} tick workers on cores {", ".join(map(str, cpus))}'
                if len(cpus) > 1 else '1 tick worker')

    def _run_ticks(self, worker: int = 0, cpu: int | None = None) -> None:
        """One tick worker: its core, its scheduling, then the compiled loop until stop."""
        name_thread(f'servo-tick{worker}')
        if cpu is not None:
            try:
                os.sched_setaffinity(0, {cpu})  # this thread only
            except OSError:
                pass  # a core taken away since: the worker still serves, unpinned
        scheduling = schedule_servo_thread(self.priority)
        if worker == 0 and self.process:  # the parent reads it (_start_process)
            dp.write_message(self.schedmsg, scheduling)
        elif worker == 0:
            self.scheduling = f'compiled nogil tick; {scheduling}; {self._workers_text()}'
            self._scheduled.set()
        try:
            nt.run(self.cfg, self.st, self.cnt, self.hand_script, self.buffers, self._scratch,
                   np.zeros(2, dtype=np.int64), self._lock)
        except Exception as exc:  # cannot happen short of a bug; say so, the device is at 0 N
            self.errors += 1
            self.last_error = exc

    def _run_bridge(self) -> None:
        name_thread('servo-bridge')
        # below the ticks; Python, so not from rtkit (its run-time limit: see .rtkit)
        schedule_servo_thread(max(self.priority - 10, 1) if self.priority > 0 else 0, rtkit=False)
        seen = -1.0
        period = self.period
        next_drain = 0
        lost_seen = back_seen = 0
        while not self._stop.is_set():
            if self.device is not None:  # the real device's losses and returns, in order
                lost, back = int(self.devst[dp.DEV.disconnects]), int(self.devst[dp.DEV.reconnects])
                if lost > lost_seen:
                    lost_seen = lost
                    self._call(self.on_disconnect, 'Falcon: device lost (servo process '
                               f'{self._pid}; disconnect {lost})')
                if back > back_seen:
                    back_seen = back
                    self._call(self.on_reconnect, f'Falcon: device back (reconnect {back})')
            if self.ctl[nt.CTL.external]:
                self._call(self._feed_hand)  # the script's own error: counted, the hand holds
            o = seq_read(self.out)
            if o is not None and o[0] != seen:
                seen = o[0]
                self._publish(o)
            next_drain += 1
            if next_drain >= 20:
                next_drain = 0
                self._drain()
            time.sleep(period * 0.5)

    def _call(self, hook, *args) -> None:
        """``hook(*args)`` on the bridge thread, if set; its own error (a publishing hiccup, a
        script's or a device hook's failure) is counted and never stops the bridge."""
        if hook is not None:
            try:
                hook(*args)
            except Exception as exc:
                self.errors += 1
                self.last_error = exc

    def _publish(self, o: np.ndarray) -> None:
        O = nt.OUT
        self.last_out = o
        t = float(o[O.t])
        stamp = int(o[O.stamp_hi]) * 1_000_000_000 + int(o[O.stamp_lo])
        state = NativeState((o[O.p0], o[O.p1], o[O.p2]), (o[O.v0], o[O.v1], o[O.v2]),
                            (int(o[O.b0]), int(o[O.b1]), 0, 0), stamp,
                            (o[O.q0], o[O.q1], o[O.q2]), t)
        self.last_state = state
        self.force = (o[O.f0], o[O.f1], o[O.f2])
        self.status = int(o[O.status])
        self.bridge_gaps.tick(t)
        self._call(self.on_state, state, self.force, t)

    def _drain(self) -> None:
        """Move the trace rows the loop wrote since the last drain into :attr:`trace`."""
        n = len(self.ring)
        if not n or self.trace is None:
            return
        w = int(self.cnt[nt.CNT.trace_w])
        if self.running:
            w -= 1  # the newest row may still be in flight
        r = self._read
        if w - r > n:
            self.trace_lost += w - r - n
            r = w - n
        if w > r:
            idx = np.arange(r, w) % n
            self.trace.extend(self.ring[idx])
        self._read = max(w, self._read)
