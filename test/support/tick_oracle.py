"""The servo tick's rules in plain Python: the test oracle the compiled tick
(``haptic_anfis.device.native_tick``) is held to, tick by tick.

- :class:`LocalModelRenderer`: the local force model's render (``haptic_anfis.device.local_model``'s
  module doc states the rules);
- :class:`ClutchMark`: the clutch / mark buttons (``haptic_anfis.device.buttons``' module doc);
- :func:`render`: what the driver's servo tick offers the safety layer from a
  :class:`~haptic_anfis.device.force_input.ForceInput` in local-model mode (the render of the
  model at the tick's position), for a :class:`~haptic_anfis.device.servo.ServoLoop`'s
  ``render`` hook.

Times are seconds; lengths metres; forces newtons; tissue frame.
"""
from __future__ import annotations

import math

from haptic_anfis.device.buttons import CLUTCH, MARK, ButtonEvents
from haptic_anfis.device.local_model import (APPROACH_RADIUS, EXPIRED, EXTRAPOLATED,
                                             FALCON_MAX_STIFFNESS, FREE, FRESH, NONE, LocalModel,
                                             RenderStats, accept_values, across_beyond,
                                             hold_offset)

__all__ = ['ClutchMark', 'LocalModelRenderer', 'render']


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
