"""The force gauge and the trainee's cue (no ROS).

The pressure levels are the exam's (config/exam.yaml): depth below the undeformed skin, light >= 2
mm, medium >= 5 mm, deep >= 8 mm — there are no agreed newton values, so the gauge's bands are
depths; the force [N] is shown beside them with the device's limit.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..device.falcon import RATED_FORCE
from ..exam.config import LEVELS

__all__ = ['DEVICE_MAX_FORCE', 'LIGHT_PRESS_S', 'Gauge', 'gauge']

#: [N] the device's force limit: the falcon driver's ``max_force`` default (the Falcon's rated
#: force, :data:`haptic_anfis.device.falcon_usb.RATED_FORCE`, 8.9 N)
DEVICE_MAX_FORCE = RATED_FORCE
#: [s] a press held this long above light but short of deep draws the "press deeper" cue
LIGHT_PRESS_S = 1.0


@dataclass(frozen=True)
class Gauge:
    """``level``: 'none', 'light', 'medium' or 'deep'; ``percent``: the depth as a share of the
    deep threshold x 1.5 (the bar's full scale), 0..100; ``force_n`` [N]; ``cue``: '' or the
    prompt; ``kind``: 'good' (the press is right), 'fix' (do something else) or ''."""
    level: str
    percent: float
    depth_mm: float
    force_n: float
    cue: str
    kind: str = ''


def gauge(depth: float, force_n: float, thresholds, in_contact: bool, light_for: float = 0.0,
          max_force: float = DEVICE_MAX_FORCE) -> Gauge:
    """The gauge for a probe ``depth`` [m] and force magnitude ``force_n`` [N]; ``thresholds``
    (light, medium, deep) [m]; ``light_for`` [s]: how long the press has stayed in contact short
    of deep. Cues: at or beyond ``max_force`` the device clamps ("beyond the device's force"); a
    press held ``LIGHT_PRESS_S`` short of deep is too light for deep coverage ("press harder");
    a press at deep is said to be right (the trainee learns the feel of it, not only its
    absence)."""
    d = max(float(depth), 0.0) if in_contact else 0.0
    k = sum(d >= t for t in thresholds)
    level = 'none' if k == 0 else LEVELS[k - 1]
    full = 1.5 * thresholds[-1]
    cue, kind = '', ''
    if force_n >= max_force:
        cue, kind = f"beyond the device's force ({max_force:g} N): ease off", 'fix'
    elif in_contact and d < thresholds[-1] and light_for >= LIGHT_PRESS_S:
        cue, kind = (f'press harder: {d * 1e3:.1f} mm is too light for deep coverage '
                     f'(>= {thresholds[-1] * 1e3:.0f} mm)'), 'fix'
    elif level == 'deep':
        cue, kind = f"that's right: deep ({d * 1e3:.1f} mm)", 'good'
    return Gauge(level, round(min(100.0, 100.0 * d / full), 1), round(d * 1e3, 2),
                 round(float(force_n), 2), cue, kind)
