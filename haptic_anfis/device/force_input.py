"""What the driver does with the force server's messages, ROS-free: stamp-age check, frame and
finiteness checks, then either the zero-order hold (``mode='zoh'``: the commanded force is the
safety layer's target until the next one) or the local force model (``mode='local_model'``: the
model is evaluated at every servo tick's position, :mod:`.local_model`).

Threads: :meth:`ForceInput.on_pose` and :meth:`ForceInput.render` run on the servo thread (in that
order, once per tick); :meth:`ForceInput.command` and :meth:`ForceInput.model` on the thread that
receives messages. Forces and positions arrive in the tissue frame; :class:`WorkspaceMapping`
takes them to the device frame for the safety layer.
"""
from __future__ import annotations

import math

from ..interfaces import LM_DEPTH
from .buttons import ClutchMark
from .falcon import DeviceState, WorkspaceMapping
from .local_model import (APPROACH_RADIUS, FALCON_MAX_STIFFNESS, LocalModel, LocalModelRenderer,
                          check_values, tissue_stiffness_limit)
from .safety import OK, REJECTED_FRAME, SafetyLayer
from .stamps import OK as STAMP_OK
from .stamps import StampBook

MODES = ('zoh', 'local_model')


class ForceInput:
    """Commands / local models in, safety-layer targets out (see the module docstring).

    Args:
        safety: the device's safety layer (device frame).
        mapping: tissue <-> device frame.
        mode: ``'zoh'`` or ``'local_model'``.
        max_stiffness: device-frame stiffness bound [N/m] (default: the Falcon's, see
            :data:`~.local_model.FALCON_MAX_STIFFNESS`).
        validity_time, validity_radius: local model expiry [s], [m] (tissue frame).
        period: servo period [s] (a model no older than 1.5 periods is "fresh").
        stamps: the book of the driver's pose stamps (a new one by default).
        clutch: the grip buttons' state machine (:class:`.buttons.ClutchMark`), or None: its
            offset moves the rendered position and its gain scales every force (zero while the
            clutch is held, no jump after it).
        approach_radius: how far [m] along an approach plane from its point it renders
            (:class:`~.local_model.LocalModelRenderer`).
        renderer: the renderer models go to (the compiled tick's,
            :class:`~.servo_native.NativeRenderer`), or None: a
            :class:`~.local_model.LocalModelRenderer` built from the arguments above.
    """

    def __init__(self, safety: SafetyLayer, mapping: WorkspaceMapping, mode: str = 'local_model',
                 max_stiffness: float = FALCON_MAX_STIFFNESS, validity_time: float = 0.05,
                 validity_radius: float = 0.005, period: float = 0.001,
                 stamps: StampBook | None = None, clutch: ClutchMark | None = None,
                 approach_radius: float = APPROACH_RADIUS,
                 renderer: LocalModelRenderer | None = None) -> None:
        if mode not in MODES:
            raise ValueError(f'mode: expected one of {MODES}, got {mode!r}')
        self.safety, self.mapping, self.mode = safety, mapping, mode
        self.clutch = clutch
        self.stamps = stamps if stamps is not None else StampBook()
        self.renderer = renderer if renderer is not None else LocalModelRenderer(
            tissue_stiffness_limit(max_stiffness, mapping.force_scale, mapping.scale),
            validity_time, validity_radius, fresh_age=1.5 * period,
            approach_radius=approach_radius)
        self.last_in_contact = False
        self.commands_received = self.models_received = 0

    @property
    def max_age(self) -> float:
        """A command or model older than this [s] at arrival is refused: the command rule
        (watchdog timeout) for the zero-order hold; for a local model the age up to which the
        renderer (the one in use: the compiled tick's holds a model) still renders one, since
        refusing it would only leave an older one. With the compiled tick's hold, refusing at
        the validity time left the held model to expire while younger ones, late beside a busy
        machine, came in (923 refused in an hour of sim without real-time priority)."""
        return self.safety.watchdog_timeout if self.mode == 'zoh' else self.renderer.max_age

    # -- servo thread -----------------------------------------------------------------------
    def on_pose(self, stamp_ns: int, now: float) -> None:
        """The driver published a pose stamped ``stamp_ns`` at monotonic ``now``."""
        self.stamps.record(stamp_ns, now)

    def render(self, state: DeviceState, now: float) -> int:
        """Local-model mode: offer the safety layer the model's force at this tick's position;
        returns the status code (-1 in zoh mode). Expired / no model: nothing is offered, so the
        safety layer holds the last force and its watchdog ramps it to zero."""
        if self.mode != 'local_model':
            return -1
        m, c = self.mapping, self.clutch
        p = m.to_tissue(state.position)
        if c is not None:
            p = c.tissue(p)
        f, status = self.renderer.render(p, now)
        if f is not None:
            if c is not None:
                g = c.gain(f, now)
                f = (g * f[0], g * f[1], g * f[2])
            self.safety.command(m.force_to_device(f), now, count=False)
        return status

    # -- receiving thread ---------------------------------------------------------------------
    def _stamp(self, stamp_ns: int, now: float) -> tuple[str, float]:
        return self.stamps.check(stamp_ns, now, self.max_age)

    def command(self, force, stamp_ns: int, frame_id: str | None, now: float) -> str:
        """A force command (3,) [N], tissue frame, answering the pose ``stamp_ns``, received at
        ``now``. A non-finite or wrong-frame command zeroes the force at once (whatever its
        stamp: zero is the safe state). Zoh mode: the safety layer's target, timed by its pose;
        local-model mode: the force itself comes with the model. Returns OK or why not."""
        self.commands_received += 1
        try:
            fx, fy, fz = force
            bad = not math.isfinite(fx + fy + fz)  # NaN or Inf in any component (or overflow)
        except (TypeError, ValueError):
            bad = True
        sf = self.safety.frame_id
        if bad or (sf and frame_id is not None and frame_id != sf):
            self.renderer.clear()
            return self.safety.command((math.nan,) * 3 if bad else (0.0,) * 3, now, frame_id)
        if self.mode != 'zoh':  # the model carries the force (and is stamp-checked itself)
            return OK
        why, t_pose = self._stamp(stamp_ns, now)
        if why != STAMP_OK:
            return f'rejected: stamp {why}'
        if self.clutch is not None:  # 0 while clutched, then no jump
            g = self.clutch.gain(force, now)
            force = tuple(g * float(v) for v in force)
        why = self.safety.command(self.mapping.force_to_device(force), t_pose, frame_id)
        if why == OK:
            self.last_in_contact = any(v != 0.0 for v in force)
        return why

    def model(self, m: LocalModel, stamp_ns: int, frame_id: str | None, now: float) -> str:
        """A local force model (tissue frame) answering the pose ``stamp_ns``, received at
        ``now`` (:meth:`model_values` of ``m.values()``; ``m.time`` is not used)."""
        try:
            v = m.values()
        except ValueError as exc:  # a malformed field: refused as model_values refuses one
            self.models_received += 1
            return 'ignored: zoh mode' if self.mode != 'local_model' else self._refuse(exc)
        return self.model_values(v, stamp_ns, frame_id, now)

    def _refuse(self, exc: ValueError) -> str:
        """A malformed / non-finite model: zero force at once, whatever its stamp."""
        self.renderer.clear()
        self.renderer.stats.rejected += 1
        self.safety.reject(f'rejected: {exc}')
        return f'rejected: {exc}'

    def model_values(self, v, stamp_ns: int, frame_id: str | None, now: float) -> str:
        """A local force model's flat values ``v`` (a message's ``position``: 26 values,
        :data:`haptic_anfis.interfaces.LOCAL_MODEL_FIELDS`), tissue frame, answering the pose
        ``stamp_ns``, received at ``now``; the model's time is that pose's time. Returns OK or
        why it was refused: a refused stamp is not taken (the current model keeps running until
        it expires); a malformed / non-finite model or a wrong frame zeroes the force at once."""
        self.models_received += 1
        if self.mode != 'local_model':
            return 'ignored: zoh mode'
        sf = self.safety.frame_id
        if sf and frame_id is not None and frame_id != sf:
            self.renderer.clear()
            self.safety.reject(f'{REJECTED_FRAME} {frame_id!r} (expected {sf!r})')
            return REJECTED_FRAME
        try:
            check_values(v)  # a malformed model zeroes the force whatever its stamp
        except ValueError as exc:
            return self._refuse(exc)
        why, t_pose = self._stamp(stamp_ns, now)
        if why != STAMP_OK:
            return f'rejected: stamp {why}'
        cur = self.renderer.time
        if cur is not None and t_pose < cur:
            return 'ignored: older than the current model'
        self.renderer.offer_values(v, t_pose, checked=True)
        self.last_in_contact = v[LM_DEPTH] > 0.0
        return OK

    # -- statistics ---------------------------------------------------------------------------
    def summary(self) -> dict:
        r, s = self.renderer.stats, self.stamps.stats
        return {'mode': self.mode, 'ticks_fresh': r.ticks_fresh,
                'ticks_extrapolated': r.ticks_extrapolated, 'ticks_expired': r.ticks_expired,
                'ticks_free': r.ticks_free, 'ticks_no_model': r.ticks_none,
                'ticks_approach': r.ticks_approach, 'models': r.models,
                'models_rejected': r.rejected, 'stiffness_clamped': r.stiffness_clamped,
                'rejected_stale': s.rejected_stale, 'rejected_future': s.rejected_future,
                'rejected_unknown_stamp': s.rejected_unknown,
                'commands_received': self.commands_received,
                'models_received': self.models_received}

    def reset_stats(self) -> None:
        """Start a new measurement window (tick counts, received counts, stamp rejections)."""
        self.renderer.reset_stats()
        self.commands_received = self.models_received = 0
        self.stamps.stats = type(self.stamps.stats)()

