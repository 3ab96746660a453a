"""What the driver does with the force server's messages, ROS-free: stamp-age check, frame and
finiteness checks, then either the zero-order hold (``mode='zoh'``: the commanded force is the
safety layer's target until the next one) or the local force model (``mode='local_model'``: the
compiled tick evaluates the model at every servo tick's position, :mod:`.local_model`).

Threads: :meth:`ForceInput.on_pose` runs where the driver publishes its pose;
:meth:`ForceInput.command` and :meth:`ForceInput.model` on the thread that receives messages.
Forces and positions arrive in the tissue frame; :class:`WorkspaceMapping` takes them to the
device frame for the safety layer.
"""
from __future__ import annotations

import math
from typing import Protocol

from ..interfaces import LM_DEPTH
from .falcon import WorkspaceMapping
from .local_model import LocalModel, check_values
from .safety import OK, REJECTED_FRAME
from .stamps import OK as STAMP_OK
from .stamps import StampBook

MODES = ('zoh', 'local_model')


class Safety(Protocol):
    """What :class:`ForceInput` asks of a safety layer (device frame):
    :class:`~.tick_views.NativeSafety`'s interface."""
    frame_id: str
    watchdog_timeout: float

    def command(self, force, now: float, frame_id: str | None = None,
                count: bool = True) -> str: ...

    def reject(self, why: str) -> None: ...


class Renderer(Protocol):
    """What :class:`ForceInput` asks of a local-model renderer (tissue frame):
    :class:`~.tick_views.NativeRenderer`'s interface."""
    time: float | None
    max_age: float

    def offer_values(self, v, time: float, checked: bool = False) -> None: ...

    def clear(self) -> None: ...

    def count_rejected(self) -> None: ...

    def reset_stats(self) -> None: ...


class ForceInput:
    """Commands / local models in, safety-layer targets out (see the module docstring).

    Args:
        safety: the device's safety layer (device frame).
        mapping: tissue <-> device frame.
        renderer: the renderer models go to (tissue frame; the compiled tick's,
            :class:`~.tick_views.NativeRenderer`).
        mode: ``'zoh'`` or ``'local_model'``.
        stamps: the book of the driver's pose stamps (a new one by default).
    """

    def __init__(self, safety: Safety, mapping: WorkspaceMapping, renderer: Renderer,
                 mode: str = 'local_model', stamps: StampBook | None = None) -> None:
        if mode not in MODES:
            raise ValueError(f'mode: expected one of {MODES}, got {mode!r}')
        self.safety, self.mapping, self.renderer, self.mode = safety, mapping, renderer, mode
        self.stamps = stamps if stamps is not None else StampBook()
        self.last_in_contact = False
        self.commands_received = self.models_received = 0

    @property
    def max_age(self) -> float:
        """A command or model older than this [s] at arrival is refused: the command rule
        (watchdog timeout) for the zero-order hold; for a local model the age up to which the
        renderer still renders one (its hold time), since refusing a younger one than the
        model it holds would only leave the older one on the hand."""
        return self.safety.watchdog_timeout if self.mode == 'zoh' else self.renderer.max_age

    # -- servo thread -----------------------------------------------------------------------
    def on_pose(self, stamp_ns: int, now: float) -> None:
        """The driver published a pose stamped ``stamp_ns`` at monotonic ``now``."""
        self.stamps.record(stamp_ns, now)

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
        self.renderer.count_rejected()
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

