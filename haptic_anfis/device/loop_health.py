"""Whether the servo loop is keeping its period, window by window while a session runs.

A loop the machine starves (no real-time priority on a busy machine) still runs: the
force the hand feels is late or held, and nothing else says so. :class:`LoopHealth` compares two
readings of the loop's counters (:meth:`~.stats.LoopStats.summary`, cumulative within a
statistics window) and names what fell short in between: the share of the periods lost above
``max_lost_pct`` (0.5 %: 995 Hz at 1 kHz, the rate the haptic loop is held to) and gaps between ticks longer than the
watchdog (the hand feels the force stop). The falcon_driver node logs it as a warning
(``loop_check_period``; at most one a minute, with how many windows fell behind so far), with
the likely cause and what to do. No ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ['LoopHealth', 'MAX_LOST_PCT', 'behind_text']

#: the loop's rate target (995 Hz at 1 kHz) as the largest share of the periods lost [%]
MAX_LOST_PCT = 0.5


@dataclass
class LoopHealth:
    """Checks successive loop summaries; ``watchdog``: the watchdog time [s] (for the message),
    ``max_lost_pct``: the largest share of the periods lost [%] a window may have."""
    watchdog: float
    max_lost_pct: float = MAX_LOST_PCT
    #: windows checked so far, and of those the ones that fell behind
    windows: int = 0
    behind: int = 0
    _last: tuple | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.watchdog) and self.watchdog > 0):
            raise ValueError(f'watchdog: expected a finite number > 0 s, got {self.watchdog!r}')
        if not (math.isfinite(self.max_lost_pct) and 0 <= self.max_lost_pct < 100):
            raise ValueError('max_lost_pct: expected a number >= 0 and < 100 %, got '
                             f'{self.max_lost_pct!r}')

    def check(self, summary: dict) -> str | None:
        """What fell short since the last call, as one line, or None. ``summary``: the loop's
        ``ticks``, ``periods_lost``, ``gaps_past_watchdog`` (cumulative over its statistics
        window), ``seconds`` [s] (the window's span so far), ``stats_resets`` (the windows
        started again) and ``max_gap_ms``. The first call, and the first after the loop's
        statistics were reset, only start a window."""
        now = (int(summary.get('stats_resets', 0)), int(summary.get('ticks', 0)),
               int(summary.get('periods_lost', 0)), int(summary.get('gaps_past_watchdog', 0)),
               float(summary.get('seconds', 0.0)))
        last, self._last = self._last, now
        if last is None or now[0] != last[0] or any(a < b for a, b in zip(now[1:], last[1:])):
            return None
        ticks, lost, long_gaps = (a - b for a, b in zip(now[1:4], last[1:4]))
        periods = ticks + lost
        if periods <= 0:
            return None
        self.windows += 1
        short = []
        pct = 100.0 * lost / periods
        if pct > self.max_lost_pct:
            short.append(f'{pct:.2f} % of its periods lost ({lost} of {periods}; at most '
                         f'{self.max_lost_pct:g} %)')
        if long_gaps:
            short.append(f'{long_gaps} gap{"s" if long_gaps > 1 else ""} between ticks longer '
                         f'than the {self.watchdog * 1e3:g} ms watchdog (the longest since the '
                         f'statistics began {float(summary.get("max_gap_ms", 0.0)):.1f} ms)')
        if not short:
            return None
        self.behind += 1
        return f'servo loop fell behind over the last {now[4] - last[4]:.1f} s: ' + '; '.join(short)


def behind_text(windows: int, behind: int, cause: str) -> str:
    """The line a trainee's page shows from the driver's report: '' while no window fell
    behind, else how many did and the ``cause`` (the driver's words: what to do)."""
    if behind <= 0:
        return ''
    return (f'the force came late in {behind} of {windows} check windows so far (the machine '
            f'starves the 1 kHz loop: what the hand feels is not the tissue alone); {cause}')


def behind_because(backend: str, realtime: bool | None, scheduling: str) -> str:
    """The likely cause of a servo loop falling behind, and what to do, in words: from the
    device ``backend``, whether its servo threads run real-time now (None: no servo thread
    found) and its start's ``scheduling`` line."""
    if realtime:
        return ('the servo is real-time: the machine itself stalled'
                + (", or the device's USB replies came late" if backend == 'falcon' else '')
                + ' (docs/servo_loop.md, "Stalls of the machine itself")')
    if realtime is False:
        return ('the servo runs under the normal scheduler; real-time priority keeps the '
                'period (docs/nodes.md, "The servo thread\'s priority")')
    return f'the servo thread\'s scheduling: {scheduling or "not reported"}'
