"""``haptic-anfis sim``: the whole haptic graph in one process, with a simulated Falcon.

falcon_driver (1 kHz servo thread, scripted virtual hand) -> contact_detector -> force_server ->
falcon_driver on one EventsExecutor, with the recorder (``--record``). The visualizer runs beside
it in a process of its own (``nodes/side_nodes.py``: in the loop's process its dent held the
interpreter lock the servo thread needs; ``--in-process`` puts it back there), and so does the
recorder with ``--recorder-process``. Prints
the loop rate, pose -> wrench latency percentiles, deadline misses, the largest applied force and
contact statistics; with ``--json`` the last line of output is one JSON object (see
``json_summary``).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

from ..cases.library import use_case_dir
from ..nodes.session import process_age
from ..nodes.side_nodes import SideNodeError
from ..realtime.processes import rerun_command_in_own_session
from ..session import OneProcessSession, add_session_arguments, spec_from_args
from ..session.spec import ONE_PROCESS_NODES
from .loop import ideal_overrides, trace_report

NAME = 'sim'


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_session_arguments(p, NAME)
    p.add_argument('--json', action='store_true',
                   help='end with one line of JSON: rate_hz, latency_p50_ms, latency_p99_ms, '
                        'latency_max_ms, deadline_misses, periods_lost, cycles, max_force_n, '
                        'contact_s, force_error_rms_pct, ripple_windows_pct, zero_force_ticks, '
                        '... (the driver traces every tick for the error figures)')
    p.add_argument('ros_args', nargs=argparse.REMAINDER,
                   help='--ros-args ... passed to rclpy (e.g. --ros-args -p rate:=500.0)')


def run(args: argparse.Namespace) -> int:
    use_case_dir(args.case_dir)   # before anything reads the library; the nodes inherit it
    code = rerun_command_in_own_session(args)  # the graph in a session of its own (fair CPU)
    if code is not None:
        return code
    spec = spec_from_args(args, NAME, nodes=ONE_PROCESS_NODES)
    trace = keep = None
    if args.json or spec.trace:  # the applied-force error needs every servo tick (loop.py)
        spec.check(check_parameters=False)   # before a temporary directory is made
        keep = Path(spec.trace).resolve() if spec.trace else None
        trace = keep or (Path(tempfile.mkdtemp(prefix='haptic-anfis-sim-'))
                         / 'falcon_driver_trace.npz')
        spec = dataclasses.replace(spec, ros_args=(*spec.ros_args, '-p',
                                                   f'falcon_driver:trace_path:={trace}'))
    session = OneProcessSession(spec)
    try:
        graph = session.start()
    except SideNodeError as exc:
        print(f'not ready: {exc}', flush=True)
        return 1
    try:
        if not session.wait_ready():
            return 1
        model = getattr(graph.force, 'model_path', None)
        print(f'ready after {process_age():.1f} s; running the haptic graph for '
              f'{args.duration:g} s (one process, EventsExecutor{session.where()})'
              + (f'; force model {model}' if model and not spec.random_case else ''),
              flush=True)
        if session.view_url():
            print(f'view: open {session.view_url()} in a browser', flush=True)
        graph.spin_for(args.duration)
    except KeyboardInterrupt:
        print('interrupted', flush=True)
    finally:
        codes = session.stop()
    summary = graph.summary()
    print_summary(summary)
    for name, code in codes.items():
        print(f'{name:<14} own process, exit code {code}')
    recorded = session.print_recorded()
    if args.json:
        out = json_summary(summary, recorded)
        out.update(_trace_figures(trace, spec, remove=keep is None),
                   graph_scheduling=session.graph_scheduling,
                   own_session=os.getsid(0) == os.getpid())
        print(json.dumps(out), flush=True)
    return 0


#: the trace report's figures ``sim --json`` carries (commands/loop.py)
TRACE_KEYS = ('force_error_rms_pct', 'force_error_rms_n', 'force_error_p99_n',
              'force_error_p99_pct', 'contact_ticks', 'ripple_windows_pct',
              'ripple_windows_ideal_pct', 'zero_force_ticks', 'longest_dropout_ms', 'force_mode',
              'watchdog_trips_in_contact', 'ticks_expired', 'ticks_held', 'ticks_beyond',
              'ticks_taken_over', 'periods_lost', 'max_gap_ms')


def _trace_figures(trace, spec, remove: bool = True) -> dict:
    """The applied-force error, ripple and dropout figures of the driver's tick trace, the ideal
    force from the session ``spec``'s parameter files, case and overrides (``remove``: a
    temporary trace, removed with its directory); {} without one."""
    if trace is None or not trace.is_file():
        return {}

    try:
        r = trace_report(trace, spec.params_files, overrides=ideal_overrides(
            [*spec.case_arguments(), *spec.user_ros_args()]))
    finally:
        if remove:
            shutil.rmtree(trace.parent, ignore_errors=True)
    return {k: r.get(k) for k in TRACE_KEYS}


def json_summary(s: dict, recorded: dict | None = None) -> dict:
    """The run's headline figures as one flat JSON-able dict (non-finite numbers become null).

    ``contact_s`` is :func:`contact_seconds`; ``cycles`` counts servo ticks.
    """
    lp, c = s['loop'], s['contact']
    out = {'rate_hz': lp['rate_hz'], 'latency_p50_ms': lp['latency_p50_ms'],
           'latency_p99_ms': lp['latency_p99_ms'], 'latency_max_ms': lp['latency_max_ms'],
           'latency_next_tick_pct': lp.get('latency_next_tick_pct'),
           'deadline_misses': lp['deadline_misses'], 'cycles': lp['ticks'],
           'periods_lost': lp.get('periods_lost'), 'max_gap_ms': lp.get('max_gap_ms'),
           'gaps_past_watchdog': lp.get('gaps_past_watchdog'),
           'loop_windows': lp.get('loop_windows'),
           'loop_windows_behind': lp.get('loop_windows_behind'),
           'max_force_n': lp['max_force_N'], 'contact_s': contact_seconds(s),
           'seconds': lp['seconds'], 'commands': lp['latency_n'],
           'watchdog_trips': lp['watchdog_trips'], 'clamped': lp['clamped'],
           'rejected': lp['rejected_nonfinite'] + lp['rejected_frame'],
           'servo_scheduling': lp.get('servo_scheduling', ''),
           'max_depth_mm': c['max_depth_mm'], 'contact_fraction': c['contact_fraction']}
    if recorded is not None:
        out.update(recorded_messages=recorded['written'], dropped_messages=recorded['dropped'])
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()}


def contact_seconds(s: dict) -> float:
    """Time in contact [s]: the run time times the share of poses found in contact."""
    return s['loop']['seconds'] * s['contact']['contact_fraction']


def print_summary(s: dict) -> None:
    lp, c, f = s['loop'], s['contact'], s['force']
    print(f"servo loop     {lp['rate_hz']:8.1f} Hz over {lp['seconds']:.1f} s "
          f"({lp['ticks']} ticks), deadline misses {lp['deadline_misses']}")
    print(f"pose->wrench   p50 {lp['latency_p50_ms']:.3f} ms, p99 {lp['latency_p99_ms']:.3f} ms, "
          f"max {lp['latency_max_ms']:.3f} ms ({lp['latency_n']} commands; "
          f"{lp.get('latency_next_tick_pct', float('nan')):.1f} % taken at the next tick)")
    print(f"force          max applied {lp['max_force_N']:.2f} N, max model {f['max_model_force_N']:.2f} N, "
          f"clamped {lp['clamped']}, watchdog trips {lp['watchdog_trips']}, "
          f"rejected {lp['rejected_nonfinite'] + lp['rejected_frame']}")
    print(f"contact        {c['in_contact']} of {c['poses']} poses in contact "
          f"({100 * c['contact_fraction']:.1f} %, ~{contact_seconds(s):.1f} s), "
          f"max depth {c['max_depth_mm']:.2f} mm, bad poses {c['bad_poses']}")
    if 'visualizer' in s:
        v = s['visualizer']
        print(f"visualizer     {v['marker_arrays']} marker arrays, {v['frames_not_drawn']} frames "
              'not drawn (no subscriber)')
