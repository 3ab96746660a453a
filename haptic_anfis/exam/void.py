"""Whether an exam can judge the trainee: a session whose haptic loop fell behind is void (no ROS).

The trainee felt the tissue only while the 1 kHz servo loop kept its rate: when one of the
falcon driver's loop-check windows fell behind, or a gap between two ticks passed the
watchdog, the forces came late or held still and what the hand felt was the machine's load,
not the tissue alone. Such a session is still scored and debriefed (nothing scored is lost),
but it is marked *void*: the trainee record keeps it and says why, and mastery leaves it out
(it counts neither for nor against the trainee).
"""
from __future__ import annotations

from typing import Mapping

__all__ = ['void_reason']


def void_reason(loop: Mapping | None) -> str | None:
    """One line saying why the session is void, from the report's ``haptic_loop`` (the
    driver's ``rate_hz``, ``loop_windows``, ``loop_windows_behind``, ``gaps_past_watchdog``);
    None when the loop kept up (or the report has no loop figures: a recorded bag's)."""
    if not loop:
        return None
    behind = int(loop.get('loop_windows_behind') or 0)
    gaps = int(loop.get('gaps_past_watchdog') or 0)
    if behind <= 0 and gaps <= 0:
        return None
    what = []
    if behind > 0:
        what.append(f'{behind} of {int(loop.get("loop_windows") or 0)} check windows behind')
    if gaps > 0:
        what.append(f'{gaps} gap{"s" * (gaps != 1)} past the watchdog')
    rate = loop.get('rate_hz')
    at = f' at {float(rate):.1f} Hz' if rate is not None else ''
    return (f'the haptic loop fell behind ({", ".join(what)}{at}): the forces felt were late, '
            'so this session does not count toward mastery')
