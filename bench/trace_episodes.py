"""Where a servo trace's bad moments came from: its longest expired-model runs and servo gaps,
each lined up with what the graph's topics did then (issue 32).

A run of ``bench_servo_load --keep DIR`` leaves, per run, the driver's tick trace
(``trace_*.npz``) and the recorder's bag. For the ``--top`` longest episodes of each kind in the
trace — runs of ticks rendered from an expired local model (older than ``model_hold_time``: the
force is zero), and gaps between ticks longer than ``--gap-ms`` — this prints when it happened
and, from the bag, for every recorded topic: the last message the recorder received before the
episode and the first after it, and how old each was (receive time minus header stamp). A topic
still flowing through an expired-model episode points at the node downstream of it; every topic
silent at once, at the recorder too, points at the whole machine or the graph's process.
``--longer-holds`` adds what each longer ``model_hold_time`` would have left of the expired runs:
a run starts when the held model turns ``--hold`` seconds old and lasts until the next model, so
under a hold of H its ticks younger than H would have rendered the held model (an upper bound:
with a longer hold the driver also takes later models, which can end a run sooner; and since
``model_hold_radius`` (the trace's meta has it) a run can also be a held model with the probe
too far from it, which no longer hold renders).
``--dropouts`` lists the runs of dropout ticks (in contact, the ideal force > 1 N, 0 N applied:
``zero_ticks`` on the servo_load pages, over the ticks from ``--from`` s) with the render status
of their ticks: ``expired`` (the hold ran out, or the probe left the hold radius) or ``free``
(the model in hand said no contact: a press onset with the graph late). ``--ripple`` lists the
ripple windows of the applied force (``ripple_pct``) that the ideal force did not have, each with
what made it: a servo gap (the force held while the hand moved on) or a step at a tick on time (a
new model, or a change of render status). The ideal force is computed at every tick as
``haptic-anfis loop`` does (minutes for an hour).

Ticks are on the driver's monotonic clock, the bag on the wall clock: the trace's
``realtime_minus_monotonic_s`` lines them up; a trace written before it existed is lined up by
its ticks' positions against the pose messages, which carry each tick's wall-clock stamp.

    .venv/bin/python bench/trace_episodes.py TRACE.npz [--bag BAG] [--top 10] [--gap-ms 10]
        [--longer-holds 0.75,1,1.5 [--hold S]] [--dropouts] [--ripple] [--from 30]

Prints only (a diagnosis, not a benchmark: no page).
"""
from __future__ import annotations

import argparse
import struct
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _args import positive_numbers  # noqa: E402
from haptic_anfis.bag.reader import read_messages  # noqa: E402
from haptic_anfis.bag.topics import (  # noqa: E402
    JOINT_STATE_TYPE, JOY_TYPE, POINT_TYPE, POSE_TYPE, TWIST_TYPE, WRENCH_TYPE)
from haptic_anfis.device.force_error import dropout_ticks, runs_of  # noqa: E402
from haptic_anfis.device.local_model import EXPIRED, STATUS_NAMES  # noqa: E402
from haptic_anfis.device.trace import DISABLED, load_trace  # noqa: E402


def episodes(rows: np.ndarray, gap_s: float, top: int) -> list[tuple[str, float, float]]:
    """(kind, start [s, monotonic], duration [s]) of the ``top`` longest expired-model runs and
    servo gaps longer than ``gap_s``, in time order."""
    t, status = rows[:, 0], rows[:, 7]
    found = []
    for a, b in zip(*runs_of(status == EXPIRED)):   # until the next tick with a usable model
        found.append(('expired model', t[a], t[min(b, len(t) - 1)] - t[a]))
    expired = sorted(found, key=lambda e: -e[2])[:top]
    dt = np.diff(t)
    idx = np.flatnonzero(dt > gap_s)
    gaps = sorted((('servo gap', t[i], dt[i]) for i in idx), key=lambda e: -e[2])[:top]
    return sorted(expired + gaps, key=lambda e: e[1])


def longer_holds(rows: np.ndarray, hold: float,
                 holds: list[float]) -> list[tuple[float, int, int, float]]:
    """(H, runs, ticks, longest run [s]) of expired-model ticks left under a ``model_hold_time``
    of each H in ``holds``, for a trace run with ``hold`` [s]: a tick ``s`` seconds into its run
    rendered a model ``hold + s`` old (ticks of a run ending at the trace's end included)."""
    t, status = rows[:, 0], rows[:, 7]
    starts, ends = runs_of(status == EXPIRED)
    out = []
    for h in holds:
        n_runs = n_ticks = 0
        longest = 0.0
        for a, b in zip(starts, ends):
            left = t[a:b][hold + (t[a:b] - t[a]) >= h - 1e-9]   # its first tick: hold old
            if len(left):
                n_runs, n_ticks = n_runs + 1, n_ticks + len(left)
                # until the next tick with a usable model, as ``episodes`` measures a run
                longest = max(longest, float(t[min(b, len(t) - 1)] - left[0]))
        out.append((h, n_runs, n_ticks, longest))
    return out


def dropout_runs(rows: np.ndarray, ideal: np.ndarray, contact: np.ndarray
                 ) -> list[tuple[float, int, float, dict[str, int]]]:
    """(start [s, monotonic], ticks, duration [s], ticks by render status name) of each run of
    dropout ticks: in ``contact``, |``ideal``| > 1 N, 0 N applied (the trace's fx fy fz)."""
    drop = dropout_ticks(np.linalg.norm(rows[:, 4:7], axis=1), np.linalg.norm(ideal, axis=1),
                         contact)
    out = []
    for a, b in zip(*runs_of(drop)):
        codes, n = np.unique(rows[a:b, 7].astype(int), return_counts=True)
        out.append((float(rows[a, 0]), int(b - a), float(rows[b - 1, 0] - rows[a, 0]),
                    {STATUS_NAMES[c] if 0 <= c < len(STATUS_NAMES) else str(c): int(k)
                     for c, k in zip(codes, n)}))
    return out


def ripple_causes(rows: np.ndarray, ideal: np.ndarray, contact: np.ndarray, gap_s: float,
                  near_s: float = 0.025) -> list[dict]:
    """What made each ripple window of the applied force that the ideal force did not have.

    For each such window (:func:`~haptic_anfis.device.force_error.ripple_windows`: 200 ms in
    contact with the applied force > 0.1 N from its centred 50 ms mean somewhere), around its
    worst tick (``near_s`` either side): the largest one-tick jump of the error (applied minus
    ideal) [N], the time before that tick [s] and the render status of the ticks either side of
    it, and the longest servo gap there [s]. ``cause`` is 'servo gap' when a gap longer than
    ``gap_s`` ends at the jump (the force held while the hand moved), else 'step' (a new model,
    or a change of render status, at a tick on time).
    """
    from haptic_anfis.device.force_error import ripple_windows
    t, f, status = rows[:, 0], rows[:, 4:7], rows[:, 7].astype(int)
    counted, bad, worst, dev = ripple_windows(t, f, contact)
    ideal_bad = ripple_windows(t, ideal, contact)[1]
    err = f - ideal
    jump = np.r_[0.0, np.linalg.norm(np.diff(err, axis=0), axis=1)]
    dt = np.r_[0.0, np.diff(t)]

    def name(c: int) -> str:
        return STATUS_NAMES[c] if 0 <= c < len(STATUS_NAMES) else str(c)

    out = []
    for w in np.flatnonzero(counted & bad & ~ideal_bad[:len(bad)]):
        i = worst[w]
        a, b = np.searchsorted(t, [t[i] - near_s, t[i] + near_s])
        j = a + int(np.argmax(jump[a:b]))
        out.append({'t': float(t[i]), 'deviation_n': float(dev[i]),
                    'jump_n': float(jump[j]), 'jump_dt_s': float(dt[j]),
                    'jump_status': f'{name(status[max(j - 1, 0)])} -> {name(status[j])}',
                    'longest_gap_s': float(dt[a:b].max()),
                    'cause': 'servo gap' if dt[j] > gap_s else 'step'})
    return out


def clock_offset(rows: np.ndarray, meta: dict, bag: Path | None) -> float | None:
    """Wall-clock minus monotonic [s]: the trace's own, or matched from the bag's poses."""
    if 'realtime_minus_monotonic_s' in meta:
        return float(meta['realtime_minus_monotonic_s'])
    if bag is None:
        return None
    from scipy.spatial import cKDTree
    # only ticks of a moving hand (> 1 um from both neighbours): a still hand's ticks lie
    # within nanometres of each other, and a pose matched the wrong one by up to seconds
    p = rows[:, 1:4]
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    at = 1 + np.flatnonzero((step[:-1] > 1e-6) & (step[1:] > 1e-6))
    tree = cKDTree(p[at])
    offsets = []
    for topic, _, _, msg in read_messages(bag, ['/falcon/measured_cp']):
        q = msg.pose.position
        d, i = tree.query((q.x, q.y, q.z))
        if d < 1e-8:   # the same tick (its position, as published)
            st = msg.header.stamp
            offsets.append(st.sec + st.nanosec * 1e-9 - rows[at[i], 0])
        if len(offsets) >= 2000:
            break
    return float(np.median(offsets)) if offsets else None


#: the recorded types that start with a std_msgs/Header (the loop's; not the session's)
HEADERED = {POSE_TYPE, TWIST_TYPE, WRENCH_TYPE, JOINT_STATE_TYPE, JOY_TYPE, POINT_TYPE}


def topic_times(bag: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """topic -> (receive times [s, wall], header stamps [s, wall; NaN without a header]). The
    stamp is read from the raw little-endian CDR (after the 4-byte encapsulation header), not by
    deserialising an hour of messages."""
    got: dict[str, tuple[list, list]] = {}
    for topic, msgtype, t_ns, raw in read_messages(bag, deserialize=False):
        r, s = got.setdefault(topic, ([], []))
        r.append(t_ns * 1e-9)
        if msgtype in HEADERED:
            sec, nsec = struct.unpack_from('<iI', raw, 4)
            s.append(sec + nsec * 1e-9)
        else:
            s.append(float('nan'))
    return {k: (np.array(r), np.array(s)) for k, (r, s) in got.items()}


def around(times: tuple[np.ndarray, np.ndarray], start: float, end: float) -> str:
    """The last message before ``start`` and the first after ``end`` [s, wall]: how long
    before / after, and their age at the recorder."""
    recv, stamp = times
    i = np.searchsorted(recv, start)
    j = np.searchsorted(recv, end, side='right')
    ms = 1e3

    def age(k: int) -> str:
        return '' if np.isnan(stamp[k]) else f' (age {(recv[k] - stamp[k]) * ms:6.1f})'
    before = (f'{(start - recv[i - 1]) * ms:7.1f} ms before{age(i - 1)}' if i > 0
              else '          none before')
    after = f'{(recv[j] - end) * ms:7.1f} ms after{age(j)}' if j < len(recv) else 'none after'
    return f'{before} | {j - i:5d} during | {after}'


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('trace', type=Path, help="a falcon_driver tick trace (.npz)")
    ap.add_argument('--bag', type=Path, help="the run's bag (default: bench_servo_load --keep's "
                                             'name beside the trace, if there)')
    ap.add_argument('--top', type=int, default=10, help='episodes of each kind (default 10)')
    ap.add_argument('--gap-ms', type=float, default=10.0,
                    help='servo gaps longer than this [ms] (default 10: the watchdog)')
    ap.add_argument('--hold', type=float,
                    help="the run's model_hold_time [s] (default: the trace's own; 0.5, the "
                         "driver's default then, for a trace from before it was written there)")
    ap.add_argument('--dropouts', action='store_true',
                    help='list the dropout runs (0 N in contact, ideal > 1 N) by render status')
    ap.add_argument('--from', dest='start', type=float, default=30.0,
                    help='--dropouts, --ripple: from this many seconds after the first tick '
                         "(default 30: bench_servo_load's --settle)")
    ap.add_argument('--ripple', action='store_true',
                    help='the ripple windows of the applied force that the ideal force did not '
                         'have, from --from s: what made each (a servo gap longer than '
                         '--ripple-gap-ms, or a step at a tick on time)')
    ap.add_argument('--ripple-gap-ms', type=float, default=3.0,
                    help='--ripple: a gap longer than this [ms] is a servo gap (default 3)')
    ap.add_argument('--longer-holds', type=positive_numbers, default=[],
                    help='comma-separated model_hold_time values [s]: the expired-model ticks '
                         'each would have left')
    a = ap.parse_args()
    rows, meta = load_trace(a.trace)
    rows = rows[rows[:, 7] != DISABLED]
    bag = a.bag
    if bag is not None and not (bag / 'metadata.yaml').is_file():
        ap.error(f'--bag {bag}: not a rosbag2 bag (expected a directory with metadata.yaml)')
    if bag is None and a.trace.name.startswith('trace_'):
        guess = a.trace.with_name(a.trace.name[len('trace_'):].removesuffix('.npz'))
        bag = guess if guess.exists() else None
    eps = episodes(rows, a.gap_ms * 1e-3, a.top)
    print(f'{a.trace}: {len(rows)} ticks over {rows[-1, 0] - rows[0, 0]:.0f} s; '
          f'{len(eps)} episodes' + (f'; bag {bag}' if bag else '; no bag'))
    offset = clock_offset(rows, meta, bag) if bag and eps else None
    topics = topic_times(bag) if bag and offset is not None else {}
    if bag and eps and offset is None:
        print('the bag could not be lined up with the trace (no matching pose)')
    elif offset is not None:   # to find the episodes in the nodes' logs (wall-clock stamps)
        print(f'first tick at {rows[0, 0] + offset:.3f} s wall clock (the logs\' stamps)')
    for kind, t0, dur in eps:
        print(f'\n{kind}: {dur * 1e3:.1f} ms at {t0 - rows[0, 0]:.3f} s after the first tick')
        for topic, times in sorted(topics.items()):
            print(f'  {topic:28s} {around(times, t0 + offset, t0 + dur + offset)}')
    if a.longer_holds:
        hold = a.hold if a.hold is not None else meta.get('model_hold_time', 0.5)
        print(f'\nexpired-model ticks left under a longer model_hold_time (run with {hold:g} s)')
        holds = [hold] + a.longer_holds
        for h, n_runs, n_ticks, longest in longer_holds(rows, hold, holds):
            print(f'  {h:6.3g} s: {n_runs:4d} runs, {n_ticks:6d} ticks, '
                  f'longest {longest * 1e3:7.1f} ms')
    if a.dropouts or a.ripple:
        from haptic_anfis.commands.loop import ideal_forces
        w = rows[rows[:, 0] - rows[0, 0] >= a.start]
        ideal, contact = ideal_forces(w[:, 1:4])
    if a.ripple:
        causes = ripple_causes(w, ideal, contact, a.ripple_gap_ms * 1e-3)
        kinds = {k: sum(c['cause'] == k for c in causes) for k in ('servo gap', 'step')}
        print(f'\nripple windows from {a.start:g} s the ideal force did not have: {len(causes)} '
              f'({kinds["servo gap"]} at a servo gap, {kinds["step"]} at a step)')
        for c in sorted(causes, key=lambda c: -c['deviation_n'])[:max(a.top, 1) * 3]:
            print(f'  {c["t"] - rows[0, 0]:9.3f} s: {c["deviation_n"]:5.2f} N off the mean; '
                  f'{c["cause"]}: error jumped {c["jump_n"]:5.2f} N after '
                  f'{c["jump_dt_s"] * 1e3:5.1f} ms ({c["jump_status"]}); longest gap near '
                  f'{c["longest_gap_s"] * 1e3:5.1f} ms')
    if a.dropouts:
        runs = dropout_runs(w, ideal, contact)
        total = sum(n for _, n, _, _ in runs)
        print(f'\ndropout runs from {a.start:g} s: {len(runs)} runs, {total} ticks')
        for t0, n, dur, kinds in runs:
            print(f'  {t0 - rows[0, 0]:9.3f} s: {n:5d} ticks, {dur * 1e3:7.1f} ms, '
                  + ', '.join(f'{k} {v}' for k, v in kinds.items()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
