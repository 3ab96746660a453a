"""The force safety rules between whatever commands a force and the device's motors (no ROS):
their outcomes and counters. The compiled servo tick runs them (:mod:`.native_tick`) once per
tick; :class:`~.tick_views.NativeSafety` takes the commands. Rules, in order:

1. Disabled (before ``start``, after ``stop``): output exactly zero, commands ignored.
2. A command holding NaN/Inf, or stamped in a frame other than ``frame_id``, is rejected: the
   target becomes zero and the output drops to zero at once (zero is the safe state; no ramp), and
   stays there until the next valid command.
3. Watchdog: when the newest valid command is older than ``watchdog_timeout`` seconds, the target
   becomes zero and the output ramps down to it at the rate limit (``max_force / max_force_rate``
   seconds from full force: 10 ms with the defaults); if the caller itself was stalled longer than
   the timeout since the previous output (a paused process), the output is zero at once: the
   ramp's time has passed already. The next valid command re-arms it. A
   command's time is the time the caller gives with it: the driver gives the
   time of its own pose the command answers (its stamp's age), not its arrival; a
   command older than the current one is ignored (out of order).
4. Rate limit: the output vector moves towards the target by at most ``max_force_rate * dt``
   (``dt`` = time since the last output, capped at ``max_dt``).
5. Clamp: the output's magnitude is at most ``max_force`` (direction kept).

Forces are (3,) newtons; time is seconds on any monotonic clock the caller chooses.
"""
from __future__ import annotations

from dataclasses import dataclass, field

OK, REJECTED_NONFINITE, REJECTED_FRAME, IGNORED_DISABLED, IGNORED_OLDER = (
    'ok', 'rejected: non-finite force', 'rejected: wrong frame', 'ignored: disabled',
    'ignored: older than the current command')


@dataclass
class SafetyStats:
    """Counters since construction."""
    commands: int = 0
    rejected_nonfinite: int = 0
    rejected_frame: int = 0
    watchdog_trips: int = 0
    watchdog_trips_in_contact: int = 0  # trips while a non-zero force was commanded
    clamped: int = 0  # outputs whose target exceeded max_force
    max_output: float = 0.0  # largest output magnitude [N]
    last_reject: str = field(default='')
