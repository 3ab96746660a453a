"""Servo loop under load: busy processes beside the haptic graph, every tick traced.

For each configuration — ``sim`` (one process: driver, contact detector, force server, recorder;
the visualizer in its own process) and ``launch`` (every node a process, with the recorder), the
driver's servo tick at real-time priority (``servo_priority`` 50, SCHED_FIFO) and without it (0:
the normal scheduler, what a user without CAP_SYS_NICE gets) — it starts ``--busy`` processes
that spin on the CPU, runs the graph for ``--duration`` s in the default force mode, and reads the
driver's figures from ``--json``: tick rate, servo periods lost, the longest gap between ticks,
the applied-force RMS error vs the ideal loop (% of the RMS ideal force), the ripple share (200 ms
windows with > 0.1 N around the 50 ms mean; the ideal force's own share beside it), the dropout
ticks (0 N applied in contact while the ideal is > 1 N) and watchdog trips in contact. ``--quiet``
adds the same runs without busy processes; ``--beside-tests`` runs the project's test suite
(``python -m pytest test``, what ``make test`` runs) beside every run, restarted when it ends.
The 1-minute load average is printed with each row
(other users of the machine add to it), and ``rt_others``: the user-space SCHED_FIFO/RR threads
already running when the run started (other users' servo threads, ahead of every normal-priority
thread). Prints the table and writes
docs/measurements/servo_load.md (``--page``).

Usage: ``python bench/bench_servo_load.py [--duration 20] [--busy 8] [--quiet]
[--configs sim:50,sim:0,launch:50,launch:0,sim:50:10] [--loops auto,native]``
(``KIND:SERVO_PRIORITY[:GRAPH_PRIORITY]``: a graph priority runs the whole graph under
``chrt -f``)
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import (LoadSampler, TestSuite, account, browser_when_up, busy, paused,  # noqa: E402
                     write_page)

CLI = [sys.executable, '-m', 'haptic_anfis.cli']
COLS = ('config', 'busy', 'load', 'steal_pct', 'rt_others', 'rate_hz', 'periods_lost',
        'max_gap_ms', 'err_rms_pct', 'ripple_pct', 'ripple_ideal_pct', 'zero_ticks', 'dropout_ms',
        'trips_contact', 'expired', 'held', 'beyond', 'taken_over', 'lat_p99_ms', 'lat_max_ms',
        'sched', 'graph')
#: with --settle: the first seconds' own columns (the browser opening its page)
SETTLE_COLS = ('settle_lost', 'settle_gap_ms', 'browser_s')


def rt_threads() -> int:
    """User-space threads scheduled SCHED_FIFO / SCHED_RR on the machine now (other users'
    servo threads: they take the CPU before any normal-priority thread)."""
    n = 0
    for stat in Path('/proc').glob('[0-9]*/task/[0-9]*/stat'):
        try:
            f = stat.read_text().rsplit(')', 1)[1].split()
            pid_stat = stat.parent.parent.parent / 'cmdline'
            if int(f[38]) in (1, 2) and pid_stat.read_bytes():  # policy; kernel threads: no cmdline
                n += 1
        except (OSError, IndexError, ValueError):
            pass
    return n


def params_file(d: Path, priority: int, loop: str, force_mode: str = '') -> Path:
    f = d / f'driver_{priority}_{loop}_{force_mode or "default"}.yaml'
    f.write_text('falcon_driver:\n  ros__parameters:\n'
                 f'    servo_priority: {priority}\n    servo_loop: {loop}\n'
                 '    trace_seconds: 0.0\n'  # every tick of the run: the figures cover it all
                 + (f'    force_mode: {force_mode}\n' if force_mode else ''))
    return f


def run_one(kind: str, priority: int, duration: float, loop: str, d: Path,
            graph_priority: int = 0, view: bool = False, force_mode: str = '',
            sim_args: tuple = (), settle: float = 0.0, launch_args: tuple = (),
            idle=contextlib.nullcontext, keep: bool = False) -> dict:
    """One run; the last JSON line of its output (or {'error': ...}). ``graph_priority`` > 0:
    the whole graph (every process and thread) runs SCHED_FIFO at it (``chrt -f``), the servo
    tick above it at ``priority``. ``view``: the browser view too (``--view``: the web_view
    node, and a headless chromium showing its page). ``settle`` > 0: the run lasts ``settle``
    seconds longer, and the figures the ticks carry are those of the last ``duration`` seconds
    (``haptic-anfis loop --from``), with the first seconds' lost periods and longest gap as
    ``settle_lost`` / ``settle_gap_ms``. ``launch_args``: more options for ``launch``. ``idle``:
    a context manager that holds the load still while the trace is read after the run.
    ``keep``: leave the trace in ``d``, with the session's output."""
    pf = params_file(d, priority, loop, force_mode)
    bag = d / f'bag_{kind}_{priority}_{time.monotonic_ns()}'
    trace = d / f'trace_{bag.name}.npz'
    run_s = str(duration + settle)
    if kind == 'sim':
        cmd = [*CLI, 'sim', '--duration', run_s, '--json', '--record', str(bag),
               '--params-file', str(pf), '--trace', str(trace), *sim_args]
    else:
        cmd = [*CLI, 'launch', '--duration', run_s, '--json', '--record', str(bag),
               '--params-file', str(pf), '--localhost', '--log-dir', str(d / f'log_{bag.name}'),
               '--trace', str(trace), *launch_args]
    if priority <= 0:  # a user without real-time rights: the graph cannot have it either
        cmd += ['--graph-priority', '0']
    if graph_priority > 0:
        cmd = ['chrt', '-f', str(graph_priority), *cmd]
    stop = browser = None
    if view:
        import threading

        from haptic_anfis.view.browser import free_port
        port = free_port()
        cmd += ['--view', '--view-port', str(port)]
        stop = threading.Event()
        browser = browser_when_up(port, stop)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, env=env,
                           timeout=duration + settle + 900)
    finally:
        if stop is not None:
            # Join: a daemon thread still closing its chromium when the benchmark exits leaves
            # that chromium drawing on the cores of whatever runs next.
            stop.set()
            browser.join(timeout=60)
    j = last_json(r.stdout)
    if j is None:
        return {'error': f'exit {r.returncode}: {(r.stdout + r.stderr)[-600:]}'}
    if settle > 0:
        try:
            with idle():
                j = settled(j, trace, pf, settle, browser.started if browser is not None
                            else None)
        except (OSError, ValueError) as exc:   # no trace, too short: this row says so
            return {'error': f'--settle: {exc}'}
    if keep:   # the session's own output beside its trace, bag and logs
        (d / f'{bag.name}.out').write_text(r.stdout + r.stderr)
    else:
        trace.unlink(missing_ok=True)
    return j


def settled(j: dict, trace: Path, pf: Path, settle: float,
            browser_at: float | None = None) -> dict:
    """``j`` with the figures the trace's ticks carry taken from ``settle`` seconds after the
    first tick on, and the first ``settle`` seconds' ``settle_lost`` / ``settle_gap_ms``;
    ``browser_s``: when the browser was started (``browser_at``, monotonic clock [s], the
    trace's), after the first tick [s]."""
    from haptic_anfis.commands.loop import trace_report
    from haptic_anfis.device.stats import tick_gaps
    from haptic_anfis.device.trace import DISABLED, load_trace
    rows, meta = load_trace(trace)
    t = rows[rows[:, 7] != DISABLED, 0]
    # up to the window's first tick: the gap across the boundary is counted here
    lost, gap = tick_gaps(t[:np.searchsorted(t, t[0] + settle) + 1], meta.get('period', 1e-3))
    w = trace_report(trace, [str(pf)], start=settle)
    windowed = ('periods_lost', 'max_gap_ms', 'ticks_expired', 'force_error_rms_pct',
                'ripple_windows_pct', 'ripple_windows_ideal_pct', 'zero_force_ticks',
                'longest_dropout_ms', 'contact_ticks')
    return {**j, **{k: w.get(k) for k in windowed},
            'rate_hz': w['rates_hz']['falcon/measured_cp'], 'rates_hz': w['rates_hz'],
            'settle_lost': lost, 'settle_gap_ms': round(gap * 1e3, 2),
            **{k: meta[k] for k in DRIVER_SETTINGS if k in meta},
            'browser_s': None if browser_at is None else round(browser_at - t[0], 1)}


#: driver parameters the page names (from the runs' trace meta, else the driver's defaults)
DRIVER_SETTINGS = ('model_blend_time', 'passivity_window')


def driver_settings(rows: list[dict]) -> str:
    """'name value s, ...' of :data:`DRIVER_SETTINGS` as the runs' traces recorded them (the
    distinct values, joined by /), or the driver's defaults where no run recorded one."""
    from haptic_anfis.nodes.falcon_driver import PARAMS
    from haptic_anfis.nodes.parameters import default_of
    out = []
    for k in DRIVER_SETTINGS:
        seen = sorted({r[k] for r in rows if r.get(k) is not None})
        values = ('/'.join(f'{v:g}' for v in seen) + ' s') if seen else \
            f'{default_of(PARAMS, k):g} s (the default)'
        out.append(f'{k} {values}')
    return ', '.join(out)


def last_json(out: str) -> dict | None:
    """The last line of a command's output that is JSON (``--json``'s summary), or None."""
    for line in reversed(out.splitlines()):
        if line.startswith('{'):
            try:
                return json.loads(line)
            except ValueError:
                break
    return None


def loop_rate(j: dict) -> float | None:
    """The servo rate of a ``sim --json`` or ``launch --json`` summary [Hz] (``launch`` gives
    the rate of the driver's published poses)."""
    rate = j.get('rate_hz')
    if rate is None and isinstance(j.get('rates_hz'), dict):
        rate = j['rates_hz'].get('falcon/measured_cp')
    return rate


def row(name: str, nbusy: int, load: float, j: dict) -> dict:
    f = lambda k: j.get(k)  # noqa: E731
    return {'config': name, 'busy': nbusy, 'load': round(load, 1), 'rate_hz': loop_rate(j),
            'periods_lost': f('periods_lost'), 'max_gap_ms': f('max_gap_ms'),
            'err_rms_pct': f('force_error_rms_pct'), 'ripple_pct': f('ripple_windows_pct'),
            'ripple_ideal_pct': f('ripple_windows_ideal_pct'), 'zero_ticks': f('zero_force_ticks'),
            'dropout_ms': f('longest_dropout_ms'), 'trips_contact': f('watchdog_trips_in_contact'),
            'expired': f('ticks_expired'), 'held': f('ticks_held'), 'beyond': f('ticks_beyond'),
            'taken_over': f('ticks_taken_over'),
            'lat_p99_ms': f('latency_p99_ms'), 'lat_max_ms': f('latency_max_ms'),
            'settle_lost': f('settle_lost'), 'settle_gap_ms': f('settle_gap_ms'),
            'browser_s': f('browser_s'), 'sched': sched_words(j.get('servo_scheduling')),
            'graph': graph_words(j.get('graph_scheduling')),
            'error': j.get('error'), **{k: j.get(k) for k in DRIVER_SETTINGS}}


def sched_words(text: str | None) -> str | None:
    """The servo thread's scheduling in a column's words: 'FIFO 50', 'RR 20 rtkit' (from
    RealtimeKit), 'normal' (the fair scheduler), from the driver's ``servo_scheduling``."""
    import re
    if not text:
        return None
    m = re.search(r'SCHED_(FIFO|RR) priority (\d+)', text)
    if m is None:
        return 'normal'
    return f'{m[1]} {m[2]}' + (' rtkit' if 'rtkit' in text else '')


def graph_words(scheduling: str | dict | None) -> str | None:
    """How the graph's nodes on the haptic path ran, in a column's words (``sim``: one process;
    ``launch``: {node: words}, the distinct ones joined by '/'): as :func:`sched_words`, with
    'pinned' where a node's threads were kept on one CPU."""
    if not scheduling:
        return None
    texts = scheduling.values() if isinstance(scheduling, dict) else [scheduling]
    words = {sched_words(t) + (' pinned' if 'kept on CPU' in t else '') for t in texts}
    return '/'.join(sorted(words))


def fmt(v) -> str:
    if v is None:
        return 'n/a'
    if isinstance(v, float):
        return f'{v:.2f}' if abs(v) < 100 else f'{v:.1f}'
    return str(v)


def main() -> int:
    import signal
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))  # run the finally blocks: no busy left
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=20.0)
    ap.add_argument('--busy', type=int, default=8)
    ap.add_argument('--quiet', action='store_true',
                    help='also run without busy processes (the first of --loops only)')
    ap.add_argument('--configs', default='sim:50,sim:0,launch:50,launch:0')
    ap.add_argument('--loops', default='auto',
                    help="the driver's servo_loop values to run, comma-separated (auto, native, "
                         "native_process; default auto, the driver's default)")
    ap.add_argument('--view', action='store_true',
                    help='the browser view too: the web_view node and a headless chromium on its '
                         'page (the loop measured with the recorder and the view running)')
    ap.add_argument('--force-mode', default='', choices=('', 'local_model', 'zoh'),
                    help="the driver's force_mode (default: its default, local_model; zoh: the "
                         "zero-order hold of the force server's commands)")
    ap.add_argument('--busy-sessions', action='store_true',
                    help='each busy process in a session of its own (other programs); by '
                         "default they share the benchmark's session, with the graph")
    ap.add_argument('--beside-tests', action='store_true',
                    help="the project's test suite (python -m pytest test) running beside "
                         'every run, restarted when it ends')
    ap.add_argument('--sim-args', default='',
                    help="more options for the sim rows, space-separated, given with '=' "
                         "(--sim-args=--recorder-process); named in the rows' config")
    ap.add_argument('--launch-args', default='',
                    help="more options for the launch rows, as --sim-args "
                         "(--launch-args=--node-sessions=each)")
    ap.add_argument('--settle', type=float, default=0.0, metavar='S',
                    help='run S seconds longer and take the figures the servo ticks carry (rate, '
                         'periods lost, gaps, force error, ripple, dropouts, expired models) '
                         'from the last --duration seconds: the view running, not a browser '
                         'opening its page; the first S seconds get columns of their own '
                         '(settle_lost, settle_gap_ms). Default 0: the whole run')
    ap.add_argument('--keep', metavar='DIR',
                    help="keep each run's tick trace, bag and node logs in DIR (default: a "
                         'temporary directory, deleted at the end): what an hour is read from '
                         'afterwards')
    ap.add_argument('--no-page', action='store_true', help='print only')
    ap.add_argument('--page', default='servo_load',
                    help='page name: docs/measurements/<page>.md (default servo_load)')
    a = ap.parse_args()
    from haptic_anfis.view.browser import chromium
    if a.view and chromium() is None:   # the browser's thread would fail, the rows go on
        print('bench_servo_load: --view: no chromium on this machine (Debian: apt-get install '
              'chromium, as .ci/run does); nothing measured', file=sys.stderr)
        return 2
    configs = [(c.split(':')[0], int(c.split(':')[1]),
                int(c.split(':')[2]) if c.count(':') > 1 else 0) for c in a.configs.split(',')]
    rows = []
    cols = columns(a)
    a.account = account()  # on the page too
    print(a.account, flush=True)
    print(' '.join(f'{c:>12}' for c in cols), flush=True)
    suite = TestSuite() if a.beside_tests else None
    if a.keep:
        Path(a.keep).mkdir(parents=True, exist_ok=True)
    with (contextlib.nullcontext(a.keep) if a.keep
          else tempfile.TemporaryDirectory(prefix='bench-servo-')) as td, \
            contextlib.ExitStack() as stack:
        if suite is not None:
            stack.callback(suite.stop)
        d = Path(td)
        loops = a.loops.split(',')
        runs = ([(0, loops[0], *c) for c in configs] if a.quiet else []) + \
            [(a.busy, lp, *c) for lp in loops for c in configs]
        for nbusy, loop, kind, prio, gprio in runs:
            if suite is not None:
                suite.ensure()
                time.sleep(20.0 if suite.starts == 1 and not rows else 0.0)  # collecting tests
            with busy(nbusy, a.busy_sessions) as procs:
                time.sleep(1.0)
                load0 = os.getloadavg()[0]
                rt = rt_threads()
                with LoadSampler() as sampled:   # through the run, not after it
                    j = run_one(kind, prio, a.duration, loop, d, gprio, a.view, a.force_mode,
                                tuple(a.sim_args.split()), a.settle,
                                launch_args=tuple(a.launch_args.split()),
                                idle=lambda: paused(procs), keep=bool(a.keep))
                load = sampled.median if sampled.median is not None else \
                    max(load0, os.getloadavg()[0])
            r = row(f'{kind} prio {prio}' + (f' graph {gprio}' if gprio else '') + f' ({loop})'
                    + (f' {a.sim_args}' if kind == 'sim' and a.sim_args else '')
                    + (f' {a.launch_args}' if kind == 'launch' and a.launch_args else ''),
                    nbusy, load, j)
            r['rt_others'] = rt
            r['steal_pct'] = None if sampled.steal is None else round(sampled.steal, 1)
            rows.append(r)
            print(' '.join(f'{fmt(r[c]):>12}' for c in cols), flush=True)
            if r['error']:
                print('  ', r['error'], flush=True)
            if not a.no_page:  # after every row: a run cut short keeps what it measured
                _page(a, rows, len(runs))
    if not a.no_page:
        print(f'page: {_page(a, rows, len(runs))}')
    return 0


def columns(a) -> tuple[str, ...]:
    return COLS + (SETTLE_COLS if a.settle > 0 else ())


def _page(a, rows: list[dict], planned: int):
    cols = columns(a)
    head = '| ' + ' | '.join(cols) + ' |\n|' + '---|' * len(cols) + '\n'
    body = (f'{a.account}.\n\n' + head
            + ''.join('| ' + ' | '.join(fmt(r[c]) for c in cols) + ' |\n' for r in rows))
    notes = (f'\n{a.duration:g} s per run after the graph is ready'
             + (f' and {a.settle:g} s more (`settle`): the figures the servo ticks carry (rate, '
                'periods lost, longest gap, force error, ripple, dropouts, expired) are the last '
                f'{a.duration:g} s\' (`haptic-anfis loop --from {a.settle:g}`); `settle_lost` and '
                '`settle_gap_ms` are the periods lost and the longest gap in the first '
                f'{a.settle:g} s (`browser_s`: when the benchmark started chromium, seconds '
                'after the first tick, as soon as the view answered; it loads the page in the '
                'seconds after, so the settle window holds that only when `browser_s` is '
                'positive (negative: chromium was started before the first traced tick); '
                'the driver\'s own counters '
                '(trips_contact, held, beyond, taken_over, latencies) cover the whole run'
                if a.settle > 0 else '') + ', '
             + (f'force mode {a.force_mode}' if a.force_mode else 'default force mode (local_model)')
             + ', recorder running'
             + (', each busy process in a session of its own' if a.busy_sessions else '')
             + (', the test suite (`python -m pytest test`) running beside every run'
                if a.beside_tests else '')
             + (', browser view running (web_view node and a headless chromium on its page)'
                if a.view else '') + '; `busy`: processes spinning beside it on the '
             f'machine\'s {os.cpu_count()} cores; `load`: the 1-minute load average, the median '
             'of readings every 10 s through the run (the machine is shared: other users add to '
             'it); `steal_pct`: CPU time the hypervisor gave other guests through the run, % of '
             'the machine\'s (this is a virtual machine: its cores then run none of its threads, '
             'the servo thread\'s neither); `rt_others`: user-space real-time threads of other '
             'processes at the start of the run (other sessions\' servo threads: they run before '
             'any normal-priority thread, so the `prio 0` rows compete with them). `rate_hz`: servo ticks per second; '
             '`periods_lost`: 1 ms periods with no tick; `max_gap_ms`: the longest time between '
             'two ticks; `err_rms_pct`: applied-force RMS error vs the ideal loop, % of the RMS '
             'ideal force; `ripple_pct`: 200 ms windows with > 0.1 N around the 50 ms mean '
             '(`ripple_ideal_pct`: the same for the ideal force itself); `zero_ticks`: ticks in '
             'contact at 0 N while the ideal force is > 1 N (`dropout_ms`: the longest run); '
             '`trips_contact`: watchdog trips in contact; `expired`: ticks whose local model had '
             'expired (older than `model_hold_time`, or held with the probe further than '
             '`model_hold_radius`); `held`: ticks rendered from a model older '
             'than its validity time, inside `model_hold_time`; `beyond`: ticks rendered with the '
             'probe beyond the model\'s validity radius (the depth followed, the offset across '
             'held at the radius); `taken_over`: ticks one tick worker took over from the other, '
             'which was preempted in the middle of its tick; `lat_p99_ms`, `lat_max_ms`: pose -> '
             'local model latency, 99th percentile and largest; `sched`: what the servo thread got '
             '(FIFO N, RR N from rtkit, normal: the fair scheduler with a short slice); `graph`: '
             'what the nodes on the haptic path got once ready (the same words, `pinned` where a '
             'node\'s threads were kept on one CPU; distinct answers of the `launch` nodes '
             'joined by /). '
             f'The driver ran with {driver_settings(rows)}. '
             'Targets (issue 32): rate >= '
             '995 Hz, zero_ticks 0, err_rms_pct <= 2, ripple_pct <= 1; quiet err_rms_pct <= 0.2.\n')
    if len(rows) < planned:
        notes += f'\n({len(rows)} of {planned} planned runs so far.)\n'
    return write_page(a.page, f'Servo loop under load ({a.loops}'
                      + (f', {a.force_mode}' if a.force_mode else '') + ')', body + notes)


if __name__ == '__main__':
    raise SystemExit(main())
