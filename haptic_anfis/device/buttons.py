"""The grip buttons (no ROS): button 0 = clutch, button 1 = mark; the rules the compiled servo
tick runs (:mod:`.native_tick`) and the offline replay of a bag's buttons follow.

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

from dataclasses import dataclass

CLUTCH, MARK = 0, 1


@dataclass
class ButtonEvents:
    """What one tick's buttons did: clutch pressed / released, mark pressed."""
    clutch_pressed: bool = False
    clutch_released: bool = False
    mark: bool = False
