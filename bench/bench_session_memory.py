"""Exam session memory over a long session: what the web view and the examiner keep per sample.

An :class:`~haptic_anfis.exam.ExamSession` of the default case is fed ``--minutes`` of samples
as the nodes feed it (1 kHz contact samples, 30 Hz probe poses, 30 Hz force commands), with the
coverage folded in at 5 Hz; printed: the Python heap it holds (tracemalloc) per contact sample,
projected to an hour, and how long the report and the debrief take over them at *stop*. For
contrast, the same rows as a list of tuples (the layout the session used before ``RowLog``).
Printed, never asserted.

    .venv/bin/python bench/bench_session_memory.py [--minutes 10]
"""
from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from pathlib import Path

from _page import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def feed(session, seconds: float, rate: float = 1000.0) -> int:
    """Samples of a probe sweeping the breast's front at 1 kHz; returns the contact samples."""
    import numpy as np

    from haptic_anfis.interfaces import CONTACT_FIELDS, I_DEPTH, I_IN_CONTACT
    v = session.surface.vertices
    lo, hi = v.min(axis=0), v.max(axis=0)
    n = int(seconds * rate)
    rng = np.random.default_rng(7)
    row = np.zeros(len(CONTACT_FIELDS))
    for i in range(n):
        t = i / rate
        row[0] = hi[0]
        row[1] = lo[1] + (hi[1] - lo[1]) * (0.5 + 0.4 * np.sin(0.3 * t))
        row[2] = lo[2] + (hi[2] - lo[2]) * (0.5 + 0.4 * np.sin(0.05 * t))
        row[I_DEPTH] = 0.01 * rng.random()
        row[I_IN_CONTACT] = 1.0
        session.add_contact_values(t, row)
        if i % 33 == 0:
            session.add_pose(t, row[:3])
            session.add_force(t, (-2.0, 0.0, 0.0))
        if i % 200 == 0:
            session.update_coverage()
    return n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--minutes', type=float, default=10.0)
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    from haptic_anfis.view.build import case_view
    cv = case_view(None, None, dent=False)
    s = cv.session
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    n = feed(s, 60.0 * a.minutes)
    held = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()   # it slows every allocation: not while the stop is timed
    from haptic_anfis.view.debrief import Debrief
    s.report()   # once before: its first call loads what every later one reuses
    t0 = time.perf_counter()
    report = s.report()
    report_s = time.perf_counter() - t0
    Debrief(report, s)
    debrief_s = time.perf_counter() - t0 - report_s
    rows = s.contacts.array()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    as_tuples = [tuple(r) for r in rows.tolist()]
    tuples = tracemalloc.get_traced_memory()[0] - base
    del as_tuples
    tracemalloc.stop()
    hour = 3600.0 / (60.0 * a.minutes)
    print(f'{a.minutes:g} min of samples: {n} contact samples at 1 kHz, {len(s.poses)} poses, '
          f'{len(s.forces)} force commands')
    print('| layout | bytes per contact sample | MB held | MB an hour (projected) |')
    print('|---|---|---|---|')
    print(f'| the session (RowLog, every stream) | {held / n:.0f} | {held / 2**20:.1f} | '
          f'{hour * held / 2**20:.0f} |')
    print(f'| the contact rows as a list of tuples (before) | {tuples / n:.0f} | '
          f'{tuples / 2**20:.1f} | {hour * tuples / 2**20:.0f} |')
    print(f'at stop, over the session: the report {report_s:.2f} s, the debrief (coverage '
          f'replay) {debrief_s:.2f} s more')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__, no_page_flags=('--no-page',)))
