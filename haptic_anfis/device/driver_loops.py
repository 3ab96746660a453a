"""The servo loops a driver runs, chosen from a table by backend and ``servo_loop`` (no ROS).

:data:`LOOPS` maps (backend, servo loop) to a builder; each builder returns a :class:`DriverLoop`:
the loop with the parts the driver wires to its topics (its safety layer, clutch and force
input), built for that loop from the start, so the driver never swaps one part for another.
Every loop is the compiled tick (:class:`~.servo_native.NativeServoLoop`), whose safety layer,
renderer and clutch are the tick's own:

- ``native`` / ``native_process`` with the simulated Falcon: on threads of the driver, or in a
  servo process of its own;
- ``native_process`` with the real Falcon: the same, the USB I/O in the servo process
  (:mod:`.device_process`).

``p`` is the driver's parameters (``haptic_anfis.nodes.falcon_params.PARAMS`` resolved).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Callable

import numpy as np

from . import falcon_usb
from .falcon import HandParams, WorkspaceMapping
from .falcon_kinematics import GEOMETRY
from .force_input import ForceInput
from .local_model import STATUS_NAMES
from .loop_health import LoopHealth
from .palpation import PalpationScript
from .safety import OK
from .servo_native import NativeServoLoop
from .stamps import STALE
from .start_gate import HeldScript
from .tick_views import NativeClutch, NativeSafety
from .trace import TickTrace, save_trace, scale_per_tick


@dataclasses.dataclass
class DriverLoop:
    """A servo loop and the parts a driver wires to it (device frame inside, tissue frame at
    the topics through :class:`~.force_input.ForceInput`)."""

    #: start / stop / stats / trace / scheduling / running / errors, its bridge and hold state
    servo: NativeServoLoop
    #: the device as the driver sees it: the compiled loop (its ``script``) with the simulated
    #: Falcon, the servo process's device counters with the real one
    device: object
    safety: NativeSafety
    #: ``update(buttons, mapped, now) -> (tissue position, events)``, ``held``
    clutch: NativeClutch
    input: ForceInput
    #: monotonic time [s] the first force command / model was taken (None: none yet); the
    #: measurement window (trace, model counts, latencies) opens there
    first_command: float | None = None
    #: the process's CPU time [s] at :attr:`first_command`
    cpu0: float = 0.0
    #: ``(t_from, force_scale)`` in time order, ``t_from`` [s] on the ticks' monotonic clock
    #: (-inf: from the start): the trace converts each tick with the scale it was rendered at
    force_scales: list[tuple[float, float]] = dataclasses.field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.force_scales:
            self.force_scales.append((-math.inf, self.servo.mapping.force_scale))

    def arrived(self, why: str, stamp_ns: int, reset_stats: bool = False,
                release_gate: Callable[[], bool] | None = None) -> None:
        """A command (zoh) / model (local_model) answering the pose ``stamp_ns`` was taken or
        refused (``why``). Answers taken or refused as stale count in the latencies (so the
        figures are not cut at the age limit) from the first one taken on, which opens the
        window (``reset_stats``: the loop statistics too). The first answer (late or not)
        releases the held simulated hand, when ``release_gate`` (if given) allows it."""
        answered = why == OK or why.endswith(STALE)
        script = getattr(self.device, 'script', None)
        if isinstance(script, HeldScript) and self.servo.held and answered \
                and (release_gate is None or release_gate()):
            script.release()
            self.servo.release()
        if why == OK and self.first_command is None:
            self.first_command = time.monotonic()
            self.cpu0 = time.process_time()
            self.input.reset_stats()
            if self.servo.trace is not None:
                self.servo.trace.clear()
            if reset_stats:
                self.servo.stats.reset()
        if self.first_command is not None and answered:
            self.servo.stats.latency((time.time_ns() - stamp_ns) * 1e-9)

    def summary(self, health: LoopHealth) -> dict:
        """The loop's statistics (:meth:`~.tick_views.NativeLoopStats.summary`), the safety
        layer's and the force input's counts, ``health``'s check windows, and the process's CPU
        (all its threads) over the wall time since the first command [%]."""
        s = self.servo.stats.summary()
        ss = self.safety.stats
        s.update(commands=ss.commands, rejected_nonfinite=ss.rejected_nonfinite,
                 rejected_frame=ss.rejected_frame, watchdog_trips=ss.watchdog_trips,
                 watchdog_trips_in_contact=ss.watchdog_trips_in_contact,
                 clamped=ss.clamped, servo_errors=self.servo.errors,
                 servo_scheduling=self.servo.scheduling, loop_windows=health.windows,
                 loop_windows_behind=health.behind, **self.input.summary())
        s.update(trace_rows_lost=self.servo.trace_lost,
                 bridge_rate_hz=self.servo.bridge_gaps.summary()['rate_hz'])
        if self.first_command is not None:
            wall = time.monotonic() - self.first_command
            s['process_cpu_pct'] = (round(100.0 * (time.process_time() - self.cpu0) / wall, 1)
                                    if wall > 0 else None)
        return s

    def set_force_scale(self, force_scale: float, max_stiffness: float) -> WorkspaceMapping:
        """Render with ``force_scale`` from the next tick, in the loop and at the force input
        (:meth:`~.servo_native.NativeServoLoop.set_force_scale`); returns the new mapping."""
        m = self.servo.set_force_scale(force_scale, max_stiffness)
        # Taken after the loop's configuration changed: a tick stamped from here on renders
        # with the new scale (one tick in flight across the switch may be counted as the old).
        self.force_scales.append((time.monotonic(), m.force_scale))
        self.input.mapping = m
        return m

    def save_trace(self, path: str, mapping: WorkspaceMapping, p: dict, frame_id: str,
                   stats: dict) -> np.ndarray:
        """Write the servo ticks in the tissue frame (position [m], applied force [N]) with
        ``stats`` to ``path`` (:func:`~.trace.save_trace`); returns the rows written. Each tick's
        force is divided by the force scale it was rendered with (:attr:`force_scales`: a case
        switched in the session changes it); ``max_force`` is the newest scale's (older readers),
        ``force_scales`` and ``device_max_force`` give each tick's
        (:func:`~.trace.max_force_per_tick`)."""
        trace = self.servo.trace
        rows = trace.arrays()
        rows[:, 1:4] = np.asarray(mapping.offset) + mapping.scale * rows[:, 1:4]
        rows[:, 4:7] /= scale_per_tick(rows[:, 0], self.force_scales)[:, None]
        scales = [[None if math.isinf(t) else t, s] for t, s in self.force_scales]
        save_trace(path, rows, stats=stats, status_names=list(STATUS_NAMES),
                   max_force=p['max_force'] / mapping.force_scale, frame_id=frame_id,
                   device_max_force=p['max_force'], force_scales=scales,
                   ticks_dropped=trace.dropped,  # the oldest, beyond the ring's bound
                   period=1.0 / p['rate'],
                   # the ticks' monotonic times onto the wall clock a bag's receive times use
                   realtime_minus_monotonic_s=time.time() - time.monotonic(),
                   model_hold_time=p['model_hold_time'], model_hold_radius=p['model_hold_radius'],
                   model_blend_time=p['model_blend_time'],
                   passivity_window=p['passivity_window'])
        return rows


@dataclasses.dataclass
class Hooks:
    """What the loop calls in the driver: ``on_state(state, force, now)`` for each tick read,
    and the real device's ``on_disconnect(message)`` / ``on_reconnect(message)``."""

    on_state: Callable
    on_disconnect: Callable[[str], None] | None = None
    on_reconnect: Callable[[str], None] | None = None


def hand_script(p: dict, default_script: str) -> tuple[HeldScript | None, str]:
    """(the simulated hand's script, held until the first force command when
    ``hold_until_force``, or None with the real Falcon; what the start's log line says of the
    device). ``default_script``: the palpation YAML when ``palpation_script`` is ''.

    Raises:
        ValueError: a script file that cannot be read (naming the file).
    """
    if p['backend'] == 'falcon':
        return None, (f"Falcon {p['device_serial'] or 'index ' + str(p['device_index'])}, "
                      f"homing {'on' if p['homing'] else 'off'}, gravity compensation "
                      f"{p['gravity_mass'] if p['gravity_compensation'] else 'off'}")
    path = p['palpation_script'] or default_script
    script = HeldScript(PalpationScript.from_yaml(path), held=p['hold_until_force'])
    return script, f'script {path} ({script.duration:.1f} s)'


def jsonable(d: dict) -> dict:
    """``d`` with its non-finite floats as None (JSON has no NaN / Inf)."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def tick_trace(p: dict) -> TickTrace | None:
    """The servo tick trace ``trace_path`` asks for: the last ``trace_seconds`` of ticks."""
    if not p['trace_path']:
        return None
    return TickTrace(max_rows=int(round(p['rate'] * p['trace_seconds'])))


def falcon_factory(p: dict) -> Callable[..., object]:
    """A callable building the USB backend from the parameters; it holds no ROS object, so the
    servo process can call it (its log and hooks are that process's own). The USB library is
    imported here, before any servo process is forked: a missing library is the driver's
    one-line error (FalconUnavailableError) at start."""
    falcon_usb.import_ftdi()
    return functools.partial(
        falcon_usb.FalconUSB, firmware_path=p['firmware_path'], device_index=p['device_index'],
        serial=p['device_serial'], firmware_attempts=p['firmware_attempts'],
        homing=p['homing'], homing_timeout=p['homing_timeout'],
        gravity_compensation=p['gravity_compensation'], gravity_mass=p['gravity_mass'],
        max_force=p['max_force'], stall_timeout=p['stall_timeout'],
        disconnect_after=p['disconnect_after'], reconnect=p['reconnect'],
        reconnect_period=p['reconnect_period'], max_motor_command=p['max_motor_command'],
        geometry=dataclasses.replace(GEOMETRY, counts_per_nm=p['counts_per_nm']))


def _hand(p: dict) -> HandParams:
    return HandParams(p['hand_mass'], p['hand_stiffness'], p['hand_damping'])


def _native(p: dict, mapping: WorkspaceMapping, frame_id: str, script, hooks: Hooks,
            **kw) -> DriverLoop:
    """The compiled, GIL-free servo loop (:mod:`.servo_native`): with the simulated Falcon
    (``script``), or with the real one opened in the servo process (``kw``: its
    ``device_factory``)."""
    loop = NativeServoLoop(
        script, mapping, _hand(p), p['rate'], p['max_force'], p['max_force_rate'],
        p['watchdog_timeout'], frame_id, p['force_mode'], p['max_stiffness'],
        p['model_validity_time'], p['model_validity_radius'], p['passivity_damping'],
        p['passivity_observer'], p['model_hold_time'], on_state=hooks.on_state,
        trace=tick_trace(p), priority=p['servo_priority'],
        process=p['servo_loop'] == 'native_process', workers=p['servo_workers'],
        approach_radius=p['model_approach_radius'], hold_radius=p['model_hold_radius'],
        blend_time=p['model_blend_time'], passivity_window=p['passivity_window'], **kw)
    # the clutch / mark rules and the renderer run in the compiled tick
    return DriverLoop(loop, loop.device if script is None else loop, loop.safety, loop.clutch,
                      ForceInput(loop.safety, mapping, loop.renderer, p['force_mode']))


def sim_native(p: dict, mapping: WorkspaceMapping, frame_id: str, script, hooks: Hooks
               ) -> DriverLoop:
    return _native(p, mapping, frame_id, script, hooks)


def falcon_native(p: dict, mapping: WorkspaceMapping, frame_id: str, script, hooks: Hooks
                  ) -> DriverLoop:
    built = _native(p, mapping, frame_id, None, hooks, device_factory=falcon_factory(p),
                    open_error=falcon_usb.FalconError,
                    open_timeout=p['homing_timeout'] + 60.0)  # firmware upload + homing
    built.servo.on_disconnect, built.servo.on_reconnect = hooks.on_disconnect, \
        hooks.on_reconnect
    return built


#: (backend, servo_loop) -> builder(p, mapping, frame_id, script, hooks) -> DriverLoop; the
#: script is the simulated hand's (None with the real Falcon)
LOOPS: dict[tuple[str, str], Callable[..., DriverLoop]] = {
    ('sim', 'native'): sim_native,
    ('sim', 'native_process'): sim_native,
    ('falcon', 'native_process'): falcon_native,
}
