"""The driver's live check of its servo loop on recorded sessions (issue 32): how many of its
``loop_check_period`` windows would have warned, trace by trace.

Each falcon_driver tick trace (``trace_path`` .npz, every tick of a session) is replayed tick by
tick through the loop's own counters (``LoopStats``, with the watchdog the session ran with) and
read every ``--period`` seconds of tick time by ``LoopHealth``, as the driver's timer does. A
check that warned in sessions that kept the period would be noise an instructor learns to
ignore; one that stayed silent where they did not would hide what the hand felt. Asserts
nothing; prints and writes docs/measurements/loop_health.md.

    .venv/bin/python bench/bench_loop_health.py TRACE [TRACE ...] [--period 10] [--no-page]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from _page import write_page
from haptic_anfis.device.loop_health import LoopHealth
from haptic_anfis.device.stats import LoopStats
from haptic_anfis.device.trace import load_trace
from haptic_anfis.nodes.falcon_driver import PARAMS
from haptic_anfis.nodes.parameters import default_of


def replay(times: np.ndarray, period: float, watchdog: float, tick_period: float
           ) -> tuple[LoopHealth, LoopStats, list[str]]:
    """(the check, the loop's counters, the warnings) of tick ``times`` [s] read every
    ``period`` [s] of tick time; ``watchdog`` [s], ``tick_period`` [s] the loop's."""
    stats = LoopStats(period=tick_period, watchdog=watchdog)
    health = LoopHealth(watchdog)
    said = []
    stats.tick(float(times[0]))
    health.check(stats.summary())
    due = times[0] + period
    for t in times[1:]:
        stats.tick(float(t))
        if t >= due:
            msg = health.check(stats.summary())
            if msg:
                said.append(msg)
            due += period
    return health, stats, said


def session_settings(trace: Path) -> tuple[str, float]:
    """(what the session was, from the benchmark's directory names; the watchdog [s] its driver
    ran with: its parameter file beside the trace, else the default)."""
    import yaml
    watchdog = default_of(PARAMS, 'watchdog_timeout')
    for f in sorted(trace.parent.glob('driver_*.yaml')):
        p = (yaml.safe_load(f.read_text()) or {}).get('falcon_driver', {})
        watchdog = float(p.get('ros__parameters', {}).get('watchdog_timeout', watchdog))
    return trace.stem.removeprefix('trace_'), watchdog


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('traces', type=Path, nargs='+', help='falcon_driver tick traces (.npz)')
    ap.add_argument('--period', type=float, default=default_of(PARAMS, 'loop_check_period'),
                    help='seconds between two checks (default: loop_check_period, 10)')
    ap.add_argument('--labels', default='',
                    help='comma-separated names for the traces in the table (default: file '
                         'names)')
    ap.add_argument('--no-page', action='store_true')
    a = ap.parse_args()
    if not a.period >= 1:
        ap.error(f'--period {a.period:g}: expected >= 1 s (as loop_check_period)')
    labels = [x.strip() for x in a.labels.split(',')] if a.labels else []
    if labels and len(labels) != len(a.traces):
        ap.error(f'--labels: {len(labels)} names for {len(a.traces)} traces')
    lines = ['| session | minutes | rate (Hz) | periods lost | gaps past the watchdog '
             '| windows | behind | behind (%) |', '|---|---|---|---|---|---|---|---|']
    examples = []
    for i, trace in enumerate(a.traces):
        rows, meta = load_trace(trace)
        name, watchdog = session_settings(trace)
        times = rows[:, 0]
        health, stats, said = replay(times, a.period, watchdog, meta.get('period') or 0.001)
        s = stats.summary()
        behind_pct = 100.0 * health.behind / health.windows if health.windows else 0.0
        lines.append(f'| {labels[i] if labels else name} | {s["seconds"] / 60:.1f} '
                     f'| {s["rate_hz"]:.1f} | {s["periods_lost"]} | {s["gaps_past_watchdog"]} '
                     f'| {health.windows} | {health.behind} | {behind_pct:.0f} |')
        print(lines[-1], flush=True)
        examples += [f'- {labels[i] if labels else name}: `{m}`' for m in said[:2]]
    text = '\n'.join(lines)
    if not a.no_page:
        body = (text + f'\n\nEvery tick of each session, read every {a.period:g} s of tick time '
                'as the driver does (`loop_check_period`). A window is *behind* when it lost '
                'more than 0.5 % of its periods (issue 32\'s 995 Hz at 1 kHz) or had a gap '
                'between ticks longer than the watchdog; the driver then logs a warning, at '
                'most one a minute, naming the likely cause (`device/loop_health.py`). The '
                'sessions are the benchmark runs named on each page of the same name '
                '(`bench/bench_servo_load.py --keep`).\n\n'
                'The first lines it would have said:\n\n' + '\n'.join(examples or ['- none'])
                + '\n')
        write_page('loop_health', "The driver's live check of its servo loop, on recorded "
                   'sessions', body)
    return 0


if __name__ == '__main__':
    sys.exit(main())
