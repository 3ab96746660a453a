"""Devices behind the servo loop: the interface, the workspace mapping and a simulated Falcon.

A device is read and written once per servo tick (:class:`Device`). Positions, velocities and
forces at this interface are in the DEVICE frame (metres, m/s, newtons); :class:`WorkspaceMapping`
takes them to and from the tissue frame the rest of the graph uses.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .palpation import PalpationScript

#: The force limit used by default [N]: Novint's published specification gives the Falcon's force
#: capability as "> 2 lb" (2 lbf = 8.9 N; Novint Falcon product specifications, 2007); we read
#: it as the continuous rating and do not ask for more. ``max_force`` overrides it.
RATED_FORCE = 8.9


@dataclass(frozen=True)
class DeviceState:
    """One reading: handle position (3,) [m], velocity (3,) [m/s], buttons (tuple of 0/1)."""
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    buttons: tuple[int, ...]


class Device:
    """What the servo loop needs from a haptic device (sim or real)."""
    max_force: float = RATED_FORCE

    def open(self, now: float) -> None:
        """Start; the motors output zero force."""

    def read(self, now: float) -> DeviceState:
        raise NotImplementedError

    def write(self, force: tuple[float, float, float]) -> None:
        """Command the motor force (3,) [N], device frame, for the coming tick."""
        raise NotImplementedError

    def close(self) -> None:
        """Stop; the motors output zero force."""


@dataclass(frozen=True)
class WorkspaceMapping:
    """Device frame <-> tissue frame: ``p_tissue = offset + scale * p_device`` (no rotation; the
    device axes are aligned with the tissue axes), ``F_device = force_scale * F_tissue``.

    With the defaults the Falcon's 10 cm cube (±5 cm) covers x in [-4.5, 10.5] cm and y, z in
    ±7.5 cm of the tissue frame: the whole breast (radii 4.5, 7, 7 cm) plus clearance.
    """
    scale: float = 1.5
    offset: tuple[float, float, float] = (0.03, 0.0, 0.0)
    force_scale: float = 1.0

    def __post_init__(self):
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f'scale: expected a finite number > 0, got {self.scale!r}')
        if len(self.offset) != 3 or not all(math.isfinite(v) for v in self.offset):
            raise ValueError(f'offset: expected 3 finite numbers [m], got {self.offset!r}')
        if not (math.isfinite(self.force_scale) and self.force_scale > 0):
            raise ValueError(f'force_scale: expected a finite number > 0, got {self.force_scale!r}')

    def to_tissue(self, p):
        s, o = self.scale, self.offset
        return (o[0] + s * p[0], o[1] + s * p[1], o[2] + s * p[2])

    def to_device(self, p):
        s, o = self.scale, self.offset
        return ((p[0] - o[0]) / s, (p[1] - o[1]) / s, (p[2] - o[2]) / s)

    def velocity_to_tissue(self, v):
        s = self.scale
        return (s * v[0], s * v[1], s * v[2])

    def force_to_device(self, f):
        k = self.force_scale
        return (k * f[0], k * f[1], k * f[2])


@dataclass(frozen=True)
class HandParams:
    """The virtual hand: handle + hand mass [kg] pulled to the script's target by a spring
    [N/m] and damper [N s/m], device frame."""
    mass: float = 0.2
    stiffness: float = 1000.0
    damping: float = 30.0

    def __post_init__(self):
        for k in ('mass', 'stiffness', 'damping'):
            v = getattr(self, k)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f'hand {k}: expected a finite number > 0, got {v!r}')


class SimulatedFalcon(Device):
    """A Novint Falcon stand-in: 10 cm cube workspace (±``half_extent``), ``max_force`` N per
    axis-free vector, a handle moved by a virtual hand following a :class:`PalpationScript`.

    Physics (device frame): ``m a = k (target - x) - c v + F_motor``, semi-implicit Euler in steps
    of at most ``dt_max``; :meth:`read` advances the simulation to ``now`` (at most ``max_catch_up``
    seconds at once, so a stalled caller does not make the handle jump). The handle stops at the
    workspace walls. The commanded motor force really pushes the handle, so the rendered tissue
    force resists the hand. The buttons are the script's (button 0 clutch, button 1 mark).
    """

    def __init__(self, script: PalpationScript, mapping: WorkspaceMapping = WorkspaceMapping(),
                 hand: HandParams = HandParams(), half_extent: float = 0.05,
                 max_force: float = RATED_FORCE, dt_max: float = 0.001, max_catch_up: float = 0.05):
        self.script, self.mapping, self.hand = script, mapping, hand
        self.half_extent, self.max_force = float(half_extent), float(max_force)
        self.dt_max, self.max_catch_up = dt_max, max_catch_up
        self._force = (0.0, 0.0, 0.0)
        self._t0 = self._t = None
        x0 = self.clip(mapping.to_device(script.target(0.0)))
        self._x, self._v = list(x0), [0.0, 0.0, 0.0]

    def clip(self, p):
        h = self.half_extent
        return tuple(min(max(c, -h), h) for c in p)

    def open(self, now: float) -> None:
        self._t0 = self._t = now
        self._force = (0.0, 0.0, 0.0)

    def close(self) -> None:
        self._force = (0.0, 0.0, 0.0)

    def write(self, force) -> None:
        fx, fy, fz = (float(v) for v in force)
        n = math.sqrt(fx * fx + fy * fy + fz * fz)
        if not math.isfinite(n):  # the device itself never takes NaN
            fx = fy = fz = 0.0
        elif n > self.max_force:
            s = self.max_force / n
            fx, fy, fz = fx * s, fy * s, fz * s
        self._force = (fx, fy, fz)

    def hand_target(self, now: float):
        """The hand's target (device frame) at ``now``."""
        return self.clip(self.mapping.to_device(self.script.target(now - (now if self._t0 is None else self._t0))))

    def read(self, now: float) -> DeviceState:
        if self._t is None:
            self.open(now)
        span = min(max(now - self._t, 0.0), self.max_catch_up)
        self._t = now
        if span > 0:
            target = self.hand_target(now)
            n = max(1, math.ceil(span / self.dt_max - 1e-9))
            dt = span / n
            m, k, c = self.hand.mass, self.hand.stiffness, self.hand.damping
            x, v, f, h = self._x, self._v, self._force, self.half_extent
            for _ in range(n):
                for i in range(3):
                    a = (k * (target[i] - x[i]) - c * v[i] + f[i]) / m
                    v[i] += a * dt
                    x[i] += v[i] * dt
                    if x[i] > h:
                        x[i], v[i] = h, min(v[i], 0.0)
                    elif x[i] < -h:
                        x[i], v[i] = -h, max(v[i], 0.0)
        b0, b1 = self.script.buttons(now - (now if self._t0 is None else self._t0))
        return DeviceState(tuple(self._x), tuple(self._v), (b0, b1, 0, 0))
