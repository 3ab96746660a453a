"""One press on a virtual spring of known stiffness, rendered on a device (real or simulated):
the stimulus of ``haptic-anfis threshold``.

The spring is a plane at ``surface_x`` (tissue frame) pushing back along +x with
``F = k * depth`` (depth = surface_x - probe x, > 0 inside). It is a local force model as the
force server sends them (:func:`spring_model`: the plane ahead of the probe, zero force at its
surface, stiffness ``-k`` along x) rendered by the compiled servo tick
(:class:`~.servo_native.NativeServoLoop`) through its safety rules (clamp, rate limit) as every
force of the simulator is. What the press measured is the stiffness the hand was given: the
least-squares slope of the applied (tissue) force against depth over the samples deeper than
``MIN_DEPTH``, the peak force and depth.

With the simulated Falcon the press runs in simulated time (its hand follows a script into the
spring and out); with a real device (:class:`DevicePresses`) one servo process holds the device
for the whole series and renders the spring for ``duration`` seconds per press while the trainee
presses, zero force between presses. No ROS.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import native_tick as nt
from .falcon import HandParams, WorkspaceMapping
from .falcon_usb import FalconError
from .local_model import model_values
from .palpation import PalpationScript
from .servo_native import NativeServoLoop

__all__ = ['MIN_DEPTH', 'DevicePresses', 'PressResult', 'SimulatedPresses', 'press_result',
           'press_script', 'simulated_press', 'spring_model']

#: [m] samples shallower than this are left out of the measured stiffness (first touch)
MIN_DEPTH = 0.001


@dataclass(frozen=True)
class PressResult:
    """What one press gave the hand: ``stiffness`` [N/m] (force / depth slope), ``peak_force``
    [N] and ``peak_depth`` [m] (tissue frame), ``samples`` in the spring."""
    stiffness: float
    peak_force: float
    peak_depth: float
    samples: int


#: [s], [m] the spring's model never expires and renders across the whole workspace
_FOREVER, _EVERYWHERE = 1e9, 1.0


def spring_model(stiffness: float, surface_x: float) -> list[float]:
    """The spring as a local force model's values (tissue frame): the plane x = ``surface_x``
    ahead of the probe (an approach model: depth 0 at its point, outward normal +x, indentation
    direction -x), no force on it, ``K = -stiffness`` along x [N/m].

    Raises:
        ValueError: ``stiffness`` not a finite number > 0 N/m.
    """
    if not (isinstance(stiffness, (int, float)) and math.isfinite(stiffness) and stiffness > 0):
        raise ValueError(f'spring stiffness: expected a finite number > 0 N/m, got '
                         f'{stiffness!r}')
    k = [-float(stiffness), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    p0 = (float(surface_x), 0.0, 0.0)
    return model_values((0.0, 0.0, 0.0), p0, k, p0, (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), 0.0,
                        False)


def press_result(depths, forces) -> PressResult:
    """What a press gave the hand from its samples: depths [m] and applied (tissue) forces [N].

    Raises:
        ValueError: fewer than 10 samples deeper than :data:`MIN_DEPTH`.
    """
    d, f = np.asarray(depths, dtype=np.float64), np.asarray(forces, dtype=np.float64)
    inside = d > MIN_DEPTH
    if inside.sum() < 10:
        raise ValueError(f'the press reached {1e3 * d.max(initial=0.0):.1f} mm into the '
                         f'spring: too shallow to measure its stiffness (press deeper than '
                         f'{MIN_DEPTH * 1e3:g} mm)')
    k = float(np.dot(d[inside], f[inside]) / np.dot(d[inside], d[inside]))
    return PressResult(k, float(f.max()), float(d.max()), int(inside.sum()))


def _spring_loop(script, mapping: WorkspaceMapping, max_force: float, rate: float,
                 **kw) -> NativeServoLoop:
    """The compiled servo loop rendering whatever spring model it is given (any frame)."""
    return NativeServoLoop(script, mapping, HandParams(), rate, max_force, frame_id='',
                           mode='local_model', validity_time=_FOREVER,
                           validity_radius=_EVERYWHERE, approach_radius=_EVERYWHERE,
                           hold_radius=_EVERYWHERE, **kw)


def press_script(surface_x: float, depth: float, duration: float = 1.0,
                 yz: tuple[float, float] = (0.0, 0.0)) -> PalpationScript:
    """The simulated hand's press: from 5 mm above the plane down to ``depth`` [m] below it and
    back, in ``duration`` [s] (tissue frame)."""
    top, bottom = surface_x + 0.005, surface_x - depth
    h = duration / 2
    return PalpationScript(np.array([0.0, h, duration]),
                           np.array([[top, *yz], [bottom, *yz], [top, *yz]]),
                           np.array([True, False]), loop=False)


def simulated_press(stiffness: float, surface_x: float = 0.045, hand_depth: float = 0.02,
                    duration: float = 1.0, mapping: WorkspaceMapping = WorkspaceMapping(),
                    max_force: float = 8.9, rate: float = 1000.0) -> PressResult:
    """One press of the simulated Falcon's hand (its target ``hand_depth`` [m] into the plane)
    on a spring of ``stiffness`` [N/m], ticked in simulated time by the compiled tick."""
    model = spring_model(stiffness, surface_x)
    loop = _spring_loop(press_script(surface_x, hand_depth, duration), mapping, max_force, rate)
    loop.safety.start(0.0)
    loop.renderer.offer_values(model, 0.0)
    dt, out, O = 1.0 / rate, loop.out, nt.OUT
    depths, forces = [], []
    for i in range(1, int(round(duration * rate)) + 1):
        loop.tick(i * dt)
        # this tick's probe (tissue frame) and the force it wrote (device frame)
        depths.append(max(surface_x - out[O.q0], 0.0))
        forces.append(math.sqrt(out[O.f0] ** 2 + out[O.f1] ** 2 + out[O.f2] ** 2)
                      / mapping.force_scale)
    return press_result(depths, forces)


@dataclass(frozen=True)
class SimulatedPresses:
    """Presses of the simulated Falcon's hand (:func:`simulated_press`, its arguments), with
    :class:`DevicePresses`'s interface: a context manager (nothing to open or close: each press
    ticks its own loop in simulated time), called with a stiffness [N/m]."""

    surface_x: float = 0.045
    hand_depth: float = 0.02
    duration: float = 1.0
    mapping: WorkspaceMapping = WorkspaceMapping()
    max_force: float = 8.9
    rate: float = 1000.0

    def __enter__(self) -> 'SimulatedPresses':
        return self

    def __exit__(self, *exc) -> None:
        return None

    def __call__(self, stiffness: float) -> PressResult:
        """One press on a spring of ``stiffness`` [N/m]."""
        return simulated_press(stiffness, self.surface_x, self.hand_depth, self.duration,
                               self.mapping, self.max_force, self.rate)


class DevicePresses:
    """Presses on a real device, one servo process for the whole series (the device is opened
    once: firmware, homing): each call renders the spring for ``duration`` [s] while the
    trainee presses, then zero force until the next. Use as a context manager (the device is
    left at zero force and closed on exit).

    Args:
        device_factory: builds the device in the servo process (e.g. ``FalconUSB``).
        surface_x: the plane's x [m], tissue frame.
        duration: seconds the spring is rendered per press.
        mapping: device <-> tissue frame.
        before: called before each press, at zero force (e.g. waits for the trainee).
        sleep: waits ``duration`` (tests pass a fake).
    """

    def __init__(self, device_factory: Callable[[], object], surface_x: float, duration: float,
                 mapping: WorkspaceMapping, max_force: float = 8.9, rate: float = 1000.0,
                 before: Callable[[], object] | None = None,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.surface_x, self.duration, self.sleep = float(surface_x), float(duration), sleep
        self.before = before
        self._samples: list[tuple[float, float]] = []
        self._on = False
        k = 1.0 / mapping.force_scale

        def sample(state, force, now: float) -> None:  # the bridge thread, newest tick
            if self._on:
                self._samples.append((max(self.surface_x - state.tissue[0], 0.0),
                                      k * math.sqrt(sum(v * v for v in force))))
        self.loop = _spring_loop(None, mapping, max_force, rate, on_state=sample,
                                 device_factory=device_factory, open_error=FalconError)

    def __enter__(self) -> 'DevicePresses':
        self.loop.start()
        return self

    def __exit__(self, *exc) -> None:
        self.loop.stop()

    def __call__(self, stiffness: float) -> PressResult:
        """One press on a spring of ``stiffness`` [N/m]."""
        model = spring_model(stiffness, self.surface_x)
        if self.before is not None:
            self.before()
        self._samples = []
        self.loop.renderer.offer_values(model, time.monotonic())
        self._on = True
        try:
            self.sleep(self.duration)
        finally:
            self._on = False
            self.loop.renderer.clear()  # no model: the watchdog ramps the force to zero
        return press_result(*zip(*self._samples)) if self._samples else press_result([], [])
