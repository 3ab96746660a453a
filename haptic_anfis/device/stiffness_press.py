"""One press on a virtual spring of known stiffness, rendered on a device (real or simulated):
the stimulus of ``haptic-anfis threshold``.

The spring is a plane at ``surface_x`` (tissue frame) pushing back along +x with
``F = k * depth`` (depth = surface_x - probe x, > 0 inside); the device renders it through the
safety layer (clamp, rate limit) as every force of the simulator is. What the press measured is
the stiffness the hand was given: the least-squares slope of the applied (tissue) force against
depth over the samples deeper than ``MIN_DEPTH``, the peak force and depth.

With the simulated Falcon the press runs in simulated time (its hand follows a script into the
spring and out); with a real device it runs in real time on a servo thread for ``duration``
seconds while the trainee presses. Pure Python, no ROS.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .falcon import Device, HandParams, SimulatedFalcon, WorkspaceMapping
from .palpation import PalpationScript
from .safety import SafetyLayer
from .servo import ServoLoop

__all__ = ['MIN_DEPTH', 'PressResult', 'SpringRender', 'press_script', 'simulated_press',
           'device_press']

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


class SpringRender:
    """The servo loop's ``render``: offers the spring's force for the tick's position and keeps
    the (depth, applied force) the previous tick gave, in the tissue frame."""

    def __init__(self, safety: SafetyLayer, mapping: WorkspaceMapping, stiffness: float,
                 surface_x: float) -> None:
        if not (math.isfinite(stiffness) and stiffness > 0):
            raise ValueError(f'spring stiffness: expected a finite number > 0 N/m, got '
                             f'{stiffness!r}')
        self.safety, self.mapping = safety, mapping
        self.stiffness, self.surface_x = float(stiffness), float(surface_x)
        self.depths: list[float] = []
        self.forces: list[float] = []
        self._depth = 0.0

    def __call__(self, state, now: float) -> int:
        p = self.mapping.to_tissue(state.position)
        d = max(self.surface_x - p[0], 0.0)
        self._depth = d
        self.safety.command(self.mapping.force_to_device((self.stiffness * d, 0.0, 0.0)), now,
                            count=False)
        return 0

    def applied(self, force) -> None:
        """The device force written this tick (device frame): paired with the tick's depth."""
        self.depths.append(self._depth)
        self.forces.append(math.sqrt(sum(v * v for v in force)) / self.mapping.force_scale)

    def result(self) -> PressResult:
        d, f = np.asarray(self.depths), np.asarray(self.forces)
        inside = d > MIN_DEPTH
        if inside.sum() < 10:
            raise ValueError(f'the press reached {1e3 * d.max(initial=0.0):.1f} mm into the '
                             f'spring: too shallow to measure its stiffness (press deeper than '
                             f'{MIN_DEPTH * 1e3:g} mm)')
        k = float(np.dot(d[inside], f[inside]) / np.dot(d[inside], d[inside]))
        return PressResult(k, float(f.max()), float(d.max()), int(inside.sum()))


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
    on a spring of ``stiffness`` [N/m], ticked in simulated time through the safety layer."""
    dev = SimulatedFalcon(press_script(surface_x, hand_depth, duration), mapping, HandParams(),
                          max_force=max_force)
    safety = SafetyLayer(max_force, frame_id='')
    spring = SpringRender(safety, mapping, stiffness, surface_x)
    loop = ServoLoop(dev, safety, rate, render=spring)
    dt = 1.0 / rate
    dev.open(0.0)
    safety.start(0.0)
    for i in range(1, int(round(duration * rate)) + 1):
        loop.tick(i * dt)
        spring.applied(loop.force)
    return spring.result()


def device_press(device: Device, stiffness: float, surface_x: float, duration: float,
                 mapping: WorkspaceMapping, max_force: float = 8.9, rate: float = 1000.0,
                 clock=time.monotonic, sleep=time.sleep) -> PressResult:
    """One press on ``device`` in real time: the servo thread renders the spring for
    ``duration`` [s] while the trainee presses; zero force after."""
    safety = SafetyLayer(max_force, frame_id='')
    spring = SpringRender(safety, mapping, stiffness, surface_x)
    loop = ServoLoop(device, safety, rate, render=spring, clock=clock,
                     on_state=lambda state, force, now: spring.applied(force))
    loop.start()
    try:
        sleep(duration)
    finally:
        loop.stop()
    return spring.result()
