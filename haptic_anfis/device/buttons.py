"""Grip buttons as a small state machine (no ROS): button 0 = clutch, button 1 = mark.

Clutch (as in Amirkhani & Nahvi's simulator, which disconnects the force simulation with the
end-effector button): while button 0 is held the probe stays where it was in the tissue frame, the
force is zero and the device-to-tissue offset follows the hand, so the trainee can re-centre the
device in its 10 cm workspace. On release the new offset is kept, and the force comes back without
a jump:

- if the force command at release is non-zero (the probe is inside the tissue), no force is passed
  until a zero command has been seen (the probe left the tissue: the next contact onset starts
  from zero force);
- then the force is ramped from 0 to 1 over ``ramp_s`` seconds.

Mark: a rising edge of button 1 (while the clutch is not held) is a "lump here" event; the caller
stamps it at the current contact point.

All positions are tissue-frame metres; ``offset`` is added to the mapped device position:
``p_tissue = mapping.to_tissue(p_device) + offset``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

CLUTCH, MARK = 0, 1


@dataclass
class ButtonEvents:
    """What one :meth:`ClutchMark.update` saw: clutch pressed / released, mark pressed."""
    clutch_pressed: bool = False
    clutch_released: bool = False
    mark: bool = False


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
