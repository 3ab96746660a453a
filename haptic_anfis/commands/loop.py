"""``haptic-anfis loop TRACE``: the haptic loop's report from a servo tick trace.

The falcon driver writes every servo tick to ``trace_path`` (.npz: time, probe position, applied
force, local-model status, tissue frame) with its loop statistics. This verb replays the traced
positions through the contact tracker and the force model configured exactly as the nodes are
(the same parameter files), i.e. the ideal loop with zero latency, and prints the applied-force
error (:mod:`haptic_anfis.device.force_error`) with the loop figures. ``haptic-anfis launch`` and
``bench/bench_loop.py`` call :func:`trace_report` at the end of a run.

Report keys (JSON): ``rates_hz`` (topic -> Hz, as the driver sees them: the poses it publishes, the
commands and local models it receives), ``latency_p50_ms``, ``latency_p99_ms``,
``latency_max_ms`` (pose stamp -> command / model arrival), ``ticks_fresh``,
``ticks_extrapolated``, ``ticks_expired`` (local model), ``watchdog_trips``,
``watchdog_trips_in_contact``, ``force_error_rms_pct``, ``force_error_rms_n``,
``force_error_p99_n``, ``force_error_p99_pct``, ``contact_ticks``, ``force_mode``,
``deadline_misses``, ``rejected_stale``, ``rejected_future``, ``rejected_unknown_stamp``,
``ticks_approach`` (of the fresh and extrapolated ticks, those rendered from an approach model:
the plane ahead of a free probe), ``force_error_by_phase`` (onset / offset / steady: the first and last 20 ms of each contact and
the rest, each ``ticks``, ``rms_n``, ``share_pct`` of the squared error),
``ripple_windows_pct``, ``ripple_windows_ideal_pct``, ``zero_force_ticks``, ``longest_dropout_ms``
(:func:`haptic_anfis.device.force_error.ripple_and_dropouts`), ``periods_lost`` (servo periods
with no tick), ``max_gap_ms`` (the longest time between two ticks), ``gaps_past_watchdog`` (gaps
between two ticks longer than the watchdog time), ``loop_windows`` and
``loop_windows_behind`` (the driver's ``loop_check_period`` windows checked, and those that fell
behind: :mod:`haptic_anfis.device.loop_health`), ``ticks_taken_over`` (ticks one tick worker
took over from the other, preempted in the middle of its tick),
``process_cpu_pct`` (the driver process's CPU time over the window / its wall time, all threads:
in one process, the whole graph's).
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..cases.library import case_node_arguments
from ..device.force_error import error_by_phase, force_error, ripple_and_dropouts
from ..device.local_model import STATUS_NAMES
from ..device.stats import tick_gaps
from ..device.trace import DISABLED, load_trace, max_force_per_tick
from ..nodes.parameter_files import parse_overrides
from ..nodes.parameters import CASE_PARAMS
from ..nodes.registry import node_parameters
from ..nodes.resim import build_pipeline
from ..pipeline.replay import pose_to_force

NAME = 'loop'

#: the keys printed first, in this order
KEYS = ('force_mode', 'rates_hz', 'latency_p50_ms', 'latency_p99_ms', 'latency_max_ms',
        'ticks_fresh', 'ticks_extrapolated', 'ticks_expired', 'watchdog_trips',
        'watchdog_trips_in_contact', 'force_error_rms_pct', 'force_error_rms_n',
        'force_error_p99_n', 'force_error_p99_pct', 'contact_ticks', 'deadline_misses',
        'rejected_stale', 'rejected_future', 'rejected_unknown_stamp')

#: the driver's statistics the report carries (its trace's ``stats``)
DRIVER_KEYS = ('latency_p50_ms', 'latency_p99_ms', 'latency_max_ms', 'ticks_fresh',
               'ticks_extrapolated', 'ticks_expired', 'watchdog_trips',
               'watchdog_trips_in_contact', 'deadline_misses', 'periods_lost', 'max_gap_ms',
               'passivity_limited', 'servo_scheduling', 'trace_rows_lost', 'ticks_held',
               'ticks_beyond', 'ticks_taken_over', 'rejected_stale', 'rejected_future',
               'rejected_unknown_stamp', 'process_cpu_pct', 'ticks_approach',
               'gaps_past_watchdog', 'loop_windows', 'loop_windows_behind')
#: of those, the ones a window (``--from``) recounts from its own ticks
WINDOWED = ('periods_lost', 'max_gap_ms', 'ticks_expired')


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('trace', help='the .npz the falcon driver wrote (parameter trace_path)')
    p.add_argument('--params-file', action='append', default=[], metavar='YAML',
                   help='ROS 2 parameter file(s) the nodes ran with (repeatable), so the replay '
                        'uses the same mesh, direction and model')
    p.add_argument('--json', action='store_true', help='print one JSON object as the last line')
    p.add_argument('--case', default='', metavar='NAME',
                   help='the case the session ran (sim / launch --case): its surface and model '
                        'make the ideal force (default: the parameter files\' or the default '
                        'scene)')
    p.add_argument('--random-case', action='store_true',
                   help='the session drew its case with --random-case --seed N')
    p.add_argument('--seed', type=int, default=None, help='seed of --random-case')
    p.add_argument('--from', dest='start', type=float, default=0.0, metavar='S',
                   help="report the ticks from S seconds after the first one the trace kept (a "
                        "session's steady state; a run longer than the trace's bound, ~10 min, "
                        "kept its newest ticks only); the driver's own counters still cover the "
                        'whole run, listed as whole_run')


#: the nodes whose parameters make the ideal force (the contact tracker, the force model)
IDEAL_NODES = ('contact_detector', 'force_server')


def ideal_overrides(ros_args: Sequence[str] = ()) -> dict[str, dict[str, Any]]:
    """{node: {parameter: value}} of :data:`IDEAL_NODES` from ``-p [node:]name:=value``
    arguments (a session's case arguments and the user's overrides), as rcl gives them to each
    node: a global name to every node that declares it, ``node:name`` to that node alone."""
    out: dict[str, dict[str, Any]] = {n: {} for n in IDEAL_NODES}
    for target, v, _ in parse_overrides(list(ros_args)):
        node, _, name = target.rpartition(':')
        for n in IDEAL_NODES:
            declared = {p.name for p in (*node_parameters(n), *CASE_PARAMS)}
            if node in ('', n) and name in declared:
                out[n][name] = v
    return out


def ideal_forces(positions: np.ndarray, params_files=(),
                 overrides: Mapping[str, Mapping[str, Any]] | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(F (n, 3) [N], in_contact (n,) bool): the contact tracker and force model (configured from
    ``params_files`` and ``overrides`` ({node: {name: value}}, :func:`ideal_overrides`) as the
    contact_detector and force_server nodes are, the session's case included) over the probe
    ``positions`` (n, 3) [m], tissue frame, in order."""
    ov = overrides or {}
    cp, tracker, _, model = build_pipeline(params_files, dict(ov.get('contact_detector', {})),
                                           dict(ov.get('force_server', {})))
    n = len(positions)
    F = np.zeros((n, 3))
    contact = np.zeros(n, dtype=bool)
    frame = cp['frame_id']
    for i, p in enumerate(np.ascontiguousarray(positions, dtype=np.float64)):
        _, c, F[i], _ = pose_to_force(tracker, model, frame, frame, p)
        contact[i] = c is not None and c.in_contact
    return F, contact


def trace_report(trace: str | Path, params_files=(), start: float = 0.0,
                 overrides: Mapping[str, Mapping[str, Any]] | None = None) -> dict:
    """The report of one trace (keys in the module docstring); the ideal force from the session's
    ``params_files`` and ``overrides`` (its case: :func:`ideal_overrides`).

    ``start`` > 0 [s]: only the ticks from ``start`` seconds after the first one (a session's
    steady state, e.g. once a browser has loaded the page). The figures the ticks carry are
    then the window's (rate, periods lost, longest gap, force error, ripple, dropouts, expired
    ticks); the driver's counters cover the whole run and are listed in ``whole_run``.

    Raises:
        ValueError: ``start`` leaves fewer than two ticks.
    """
    rows, meta = load_trace(trace)
    kept = len(rows)
    rows = rows[rows[:, 7] != DISABLED]  # 0 N on purpose (before start, at shutdown)
    st = meta.get('stats', {})
    # a long run's trace keeps only its newest rows (the driver's ``trace_seconds``)
    dropped = int(meta.get('ticks_dropped') or 0)
    if start > 0 and dropped:
        raise ValueError(f'{trace}: --from {start:g} s: the trace kept only its newest ticks '
                         f'({dropped} older ones dropped: the driver\'s trace_seconds), so the '
                         'first tick is not the run\'s')
    if start > 0:
        if len(rows) < 2 or rows[-1, 0] - rows[0, 0] <= start:
            span = float(rows[-1, 0] - rows[0, 0]) if len(rows) > 1 else 0.0
            raise ValueError(f'{trace}: --from {start:g} s: the trace has {span:.1f} s of ticks')
        rows = rows[rows[:, 0] >= rows[0, 0] + start]
        period = meta.get('period') or float(np.median(np.diff(rows[:, 0])))
        lost, gap = tick_gaps(rows[:, 0], period)
        expired = None if st.get('mode') == 'zoh' else \
            int(np.sum(rows[:, 7] == STATUS_NAMES.index('expired')))   # zoh traces no model
        st = {k: v for k, v in st.items() if k not in ('commands_received', 'models_received')}
        st.update(zip(WINDOWED, (lost, gap * 1e3, expired)))
    F, contact = ideal_forces(rows[:, 1:4], params_files, overrides)
    fmax = max_force_per_tick(rows, meta)   # per tick: a case switch changes the scale
    err = force_error(rows[:, 4:7], F, contact, max_force=fmax)
    err['force_error_by_phase'] = error_by_phase(rows[:, 4:7], F, contact, rows[:, 0],
                                                 max_force=fmax)
    err.update(ripple_and_dropouts(rows[:, 0], rows[:, 4:7], F, contact, max_force=fmax))
    # the trace and the received counts start at the first command (the driver resets them)
    secs = float(rows[-1, 0] - rows[0, 0]) if len(rows) > 1 else 0.0
    # The received counts cover the whole run, the dropped rows' time is taken at the kept rows'
    # tick rate.
    counted = secs * (kept + dropped) / kept if kept else 0.0
    rate = lambda k: round(st[k] / counted, 1) if counted > 0 and k in st else None  # noqa: E731
    r = {'force_mode': st.get('mode'),
         'rates_hz': {'falcon/measured_cp': round((len(rows) - 1) / secs, 1) if secs else None,
                      'falcon/servo_cf': rate('commands_received'),
                      'falcon/servo_cf_local': rate('models_received')},
         **{k: st.get(k) for k in DRIVER_KEYS},
         **err, 'ticks': int(len(rows)), 'ticks_dropped': dropped}
    if start > 0:   # the driver's counters not recounted from the window's ticks
        r['from_s'] = start
        r['whole_run'] = sorted(k for k in DRIVER_KEYS if k not in WINDOWED
                                and k != 'servo_scheduling' and r.get(k) is not None)
    return {k: r[k] for k in KEYS if k in r} | {k: v for k, v in r.items() if k not in KEYS}


def format_report(r: dict) -> str:
    """Human-readable lines of :func:`trace_report`'s dict."""
    f = lambda v, d=2: 'n/a' if v is None else (f'{v:.{d}f}' if isinstance(v, float) else str(v))  # noqa: E731
    rates = ', '.join(f'{t} {f(v, 0)}' for t, v in r['rates_hz'].items())
    return '\n'.join([
        f"loop ({r['force_mode']}): rates Hz: {rates}",
        f"  pose->command latency ms: p50 {f(r['latency_p50_ms'])} p99 {f(r['latency_p99_ms'])} "
        f"max {f(r['latency_max_ms'])}; deadline misses {r['deadline_misses']}",
        f"  local model ticks: fresh {r['ticks_fresh']} extrapolated {r['ticks_extrapolated']} "
        f"expired {r['ticks_expired']}; watchdog trips {r['watchdog_trips']} "
        f"(in contact {r['watchdog_trips_in_contact']}); stamps refused: stale "
        f"{r['rejected_stale']} future {r['rejected_future']} unknown "
        f"{r['rejected_unknown_stamp']}",
        f"  applied-force error over {r['contact_ticks']} contact ticks: RMS "
        f"{f(r['force_error_rms_n'], 3)} N = {f(r['force_error_rms_pct'])} % of the RMS force, "
        f"p99 {f(r['force_error_p99_n'], 3)} N ({f(r['force_error_p99_pct'])} % per tick, "
        f"forces >= 0.5 N)",
        f"  ripple: {f(r.get('ripple_windows_pct'))} % of 200 ms windows > 0.1 N around the "
        f"50 ms mean (ideal force: {f(r.get('ripple_windows_ideal_pct'))} %); dropouts: "
        f"{r.get('zero_force_ticks')} ticks at 0 N with the ideal > 1 N (longest "
        f"{f(r.get('longest_dropout_ms'), 1)} ms)",
        f"  servo ticks: {r.get('ticks')} traced"
        + (f" (the newest; {r['ticks_dropped']} older not kept: trace_seconds)"
           if r.get('ticks_dropped') else '') + f"; periods lost {r.get('periods_lost')}, longest "
        f"gap {f(r.get('max_gap_ms'))} ms, taken over {r.get('ticks_taken_over')}",
        _phase_line(r.get('force_error_by_phase'))]
        + ([f"  from {r['from_s']:g} s after the first tick; the whole run's: "
            + ', '.join(r['whole_run'])] if r.get('from_s') else []))


def _phase_line(ph: dict | None) -> str:
    """Where the error is: onset / offset / steady (first / last 20 ms of each contact)."""
    if not ph:
        return '  error by phase: n/a'
    f = lambda v, d: 'n/a' if v is None else f'{v:.{d}f}'  # noqa: E731
    parts = [f"{k} {ph[k]['ticks']} ticks RMS {f(ph[k]['rms_n'], 3)} N "
             f"({f(ph[k]['share_pct'], 0)} % of the squared error)" for k in ('onset', 'offset',
                                                                            'steady')]
    return f"  error by phase over {ph['contacts']} contacts (20 ms windows): " + '; '.join(parts)


def run(args: argparse.Namespace) -> int:
    if not Path(args.trace).is_file():
        raise ValueError(f'{args.trace}: no such trace file')
    if args.start < 0:
        raise ValueError(f'--from: expected seconds >= 0, got {args.start:g}')
    r = trace_report(args.trace, args.params_file, args.start,
                     ideal_overrides(case_node_arguments(args)))
    print(format_report(r))
    if args.json:
        print(json.dumps(r))
    return 0


# -- used by haptic-anfis launch (kept here so launch.py only calls two functions) --------------
def launch_trace_path(extra: dict[str, list[str]], where: Path | None,
                      trace: str | None = None) -> Path | None:
    """Ask the falcon driver of a launch (``extra``: node -> extra ROS args) to write its tick
    trace: to ``trace`` (``--trace``), else a new file in ``where`` (the log dir) or a temporary
    directory. None: no driver."""
    if 'falcon_driver' not in extra:
        return None
    if trace:
        path = Path(trace).resolve()
    else:
        d = Path(where) if where else Path(tempfile.mkdtemp(prefix='haptic_anfis_loop_'))
        path = (d / 'falcon_driver_trace.npz').resolve()
    extra['falcon_driver'] += ['-p', f'trace_path:={path}']
    return path


def print_launch_report(trace: Path | None, params_files, as_json: bool,
                        ros_args: Sequence[str] = (), **extra) -> None:
    """The loop report of a finished launch (nothing if the driver left no trace); ``ros_args``:
    the nodes' ``-p`` arguments (the case's: :func:`ideal_overrides`); ``extra`` goes into the
    JSON object (``graph_scheduling``: {node: how it was scheduled})."""
    if trace is None:
        return
    if not trace.is_file():
        print(f'loop report: the falcon driver wrote no trace ({trace})', flush=True)
        return
    r = trace_report(trace, params_files, overrides=ideal_overrides(ros_args))
    print(format_report(r), flush=True)
    if as_json:
        print(json.dumps({**r, **extra}), flush=True)
