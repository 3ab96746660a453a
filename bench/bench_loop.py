"""Haptic loop benchmark: zero-order hold vs local force model, in one process and across processes.

For each configuration — one process (EventsExecutor, no visualizer), separate processes
(falcon_driver, contact_detector, force_server), and separate processes with two busy processes
started by the bench (pure-Python spin loops, one per core of a 2-core machine) — the driver runs
once with ``force_mode:=zoh`` (today's zero-order hold of the newest force) and once with
``force_mode:=local_model`` (F0 + K (p - p0) evaluated every servo tick), each for ``--seconds``
of measurement after the first force command, writing its servo tick trace. Printed per run: the
servo rate, pose -> command latency p50/p99/max, ticks rendered from a fresh / extrapolated /
expired local model, watchdog trips while in contact, and the applied-force error against the
ideal loop (the force model at each tick's own pose, zero latency; :mod:`haptic_anfis.commands.
loop`): RMS as % of the RMS force, RMS and p99 in N. Then the ZOH / local-model error ratio per
configuration. Printed, never asserted: the machine is shared (the load average is printed).
Target (issue 17): local model, separate processes under load: RMS <= 2 % of the force, >= 5x
better than the zero-order hold in the same run, no watchdog trip in contact.

    .venv/bin/python bench/bench_loop.py [--seconds 10] [--json] [--configs one,multi,busy]
                                         [--keep DIR] [--approach-distance M] [--executor-input]

Columns: ``miss`` = servo deadline misses (a tick started more than a period late), ``cpu%`` = the
driver process's CPU over the run (all threads; in one process, the whole graph's), ``µs/tick`` (one
process) = the whole graph's CPU per servo tick, measured by the bench: on a shared machine the
servo rate follows the load, the CPU each tick costs much less so.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import tempfile
from pathlib import Path

from harness import loop_in_one_process, loop_in_processes, run_with_page  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MODES = ('zoh', 'local_model')


def row(name: str, r: dict) -> str:
    f = lambda v, d=2: 'n/a' if v is None else f'{v:.{d}f}'  # noqa: E731
    return (f'{name:<30} {r["force_mode"]:<11} {r["rates_hz"]["falcon/measured_cp"] or 0:>7.1f} '
            f'{f(r["latency_p50_ms"]):>6} {f(r["latency_p99_ms"]):>6} {f(r["latency_max_ms"]):>6} '
            f'{r["ticks_fresh"]:>6} {r["ticks_extrapolated"]:>6} {r["ticks_expired"]:>5} '
            f'{r["watchdog_trips_in_contact"]:>4} {f(r["force_error_rms_pct"]):>7} '
            f'{f(r["force_error_rms_n"], 3):>7} {f(r["force_error_p99_n"], 3):>7} '
            f'{r["contact_ticks"]:>7} {r.get("deadline_misses") or 0:>5} '
            f'{f(r.get("process_cpu_pct"), 0):>4} {f(r.get("cpu_us_per_tick"), 0):>6}')


def main() -> int:
    from haptic_anfis.commands.loop import trace_report
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=10.0)
    ap.add_argument('--configs', default='one,multi,busy',
                    help='comma-separated subset of one, multi, busy')
    ap.add_argument('--json', action='store_true', help='also print each run as a JSON line')
    ap.add_argument('--keep', metavar='DIR', help='write the servo tick traces here (kept: '
                    "read them with 'haptic-anfis loop DIR/<config>_<mode>.npz') instead of a "
                    'temporary directory')
    ap.add_argument('--approach-distance', type=float, metavar='M',
                    help="the contact detector's approach_distance [m] (0 = no approach model; "
                         "default: the node's)")
    ap.add_argument('--executor-input', action='store_true',
                    help="the driver takes its loop inputs in executor callbacks "
                         "(take_in_servo_thread false), as before the servo thread took them")
    a = ap.parse_args()
    driver = {'take_in_servo_thread': False} if a.executor_input else {}
    contact = ({} if a.approach_distance is None
               else {'approach_distance': float(a.approach_distance)})
    cpu: dict[Path, float] = {}   # one process: the graph's CPU seconds over the window

    def one(s, m, t):
        cpu[t] = loop_in_one_process(s, m, t, driver, contact)

    configs = {'one': ('one process', one),
               'multi': ('separate processes',
                         lambda s, m, t: loop_in_processes(s, m, t, 0, driver, contact)),
               'busy': ('separate + 2 busy processes',
                        lambda s, m, t: loop_in_processes(s, m, t, 2, driver, contact))}
    print(f'haptic loop at 1 kHz, {a.seconds:g} s per run, {os.cpu_count()} CPUs, '
          f'load average {os.getloadavg()[0]:.2f} (1 min) at start')
    print(f'{"configuration":<30} {"mode":<11} {"rate Hz":>7} {"p50 ms":>6} {"p99 ms":>6} '
          f'{"max ms":>6} {"fresh":>6} {"extrap":>6} {"expir":>5} {"wdog":>4} {"err %":>7} '
          f'{"RMS N":>7} {"p99 N":>7} {"contact":>7} {"miss":>5} {"cpu%":>4} {"µs/tick":>6}')
    ratios = []
    if a.keep:
        Path(a.keep).mkdir(parents=True, exist_ok=True)
    with (contextlib.nullcontext(a.keep) if a.keep
          else tempfile.TemporaryDirectory(prefix='bench_loop_')) as tmp:
        for key in a.configs.split(','):
            name, fn = configs[key]
            res = {}
            for mode in MODES:
                trace = Path(tmp) / f'{key}_{mode}.npz'
                try:
                    load0 = os.getloadavg()[0]
                    fn(a.seconds, mode, trace)
                    r = trace_report(trace)
                    if trace in cpu and r.get('ticks'):
                        r['cpu_us_per_tick'] = 1e6 * cpu[trace] / r['ticks']
                    r['load_1min'] = round((load0 + os.getloadavg()[0]) / 2, 2)
                    res[mode] = r
                    print(row(name, r), f' load {r["load_1min"]:.1f}', flush=True)
                    if a.json:
                        print(json.dumps({'configuration': name, **r}), flush=True)
                except Exception as exc:  # a failed run is reported, the others still run
                    print(f'{name:<30} {mode:<11} failed: {exc}', flush=True)
            z, lm = res.get('zoh'), res.get('local_model')
            if z and lm and z['force_error_rms_n'] and lm['force_error_rms_n']:
                ratios.append(f'{name}: ZOH / local model RMS error = '
                              f'{z["force_error_rms_n"] / lm["force_error_rms_n"]:.1f}x')
    for line in ratios:
        print(line)
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
