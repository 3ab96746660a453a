"""Soak benchmark: a long session, one process with recording, then separate processes.

Prints one row per interval (default a minute) for each configuration: servo rate, pose->wrench
latency p99 and max, deadline misses, the resident memory (RSS) of every node and the bag size, so
what degrades over a session-length run shows (garbage collection pauses, bag chunk flushes,
queues, memory growth). Usage: ``python bench/bench_soak.py [--one-minutes 10] [--multi-minutes
10] [--interval 60]`` (issue 20; issue 21 reads the RSS and bag size columns).

- one process: ``haptic-anfis sim``'s graph (driver, contact detector, force server, no
  visualizer) plus the recorder of every loop topic, in the same process as ``sim --record`` runs
  it (``--recorder-process``: in a process of its own); figures from the driver's own statistics
  (latency = pose stamp -> command arrival at the driver; a miss = a servo tick more than one
  period late).
- multi process: ``haptic-anfis launch --record`` (recorder, force server, contact detector,
  driver as processes); figures from an observer node in this process: rate of poses received,
  latency = pose stamp -> command received here, "misses" = pose gaps > 2 periods seen here
  (includes DDS delivery jitter, so an upper bound on the driver's misses).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from harness import account, busy, run_with_page, stop_launch  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def rss_mb(pid: int | str = 'self') -> float:
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float('nan')


def dir_mb(path: Path) -> float:
    return sum(f.stat().st_size for f in Path(path).rglob('*') if f.is_file()) / 2**20 \
        if Path(path).exists() else 0.0


HEADER = (f'{"min":>5} {"rate Hz":>8} {"p99 ms":>7} {"max ms":>7} {"misses":>7} {"n":>7} '
          f'{"bag MB":>7}  RSS MB per node')


def row(t_min, rate, lat, misses, bag, rss: dict) -> str:
    """One interval's line; ``lat``: the interval's latencies [s] (an array), or (p99, max, n)
    already computed (from the driver's histogram)."""
    if isinstance(lat, tuple):
        p99, mx, n = lat[0] * 1e3, lat[1] * 1e3, lat[2]
    else:
        p99 = np.percentile(lat, 99) * 1e3 if len(lat) else float('nan')
        mx = lat.max() * 1e3 if len(lat) else float('nan')
        n = len(lat)
    return (f'{t_min:5.1f} {rate:8.1f} {p99:7.3f} {mx:7.3f} {misses:7d} {n:7d} {bag:7.1f}  '
            + ' '.join(f'{k} {v:.1f}' for k, v in rss.items()))


def interval_latency(hist, counts_before: np.ndarray) -> tuple[tuple[float, float, int], np.ndarray]:
    """(p99 [s], max [s], n) of the latencies the driver's histogram (device.stats) recorded since
    ``counts_before`` (within its 0.5 % bins; the max is the top bin's value), and the counts now."""
    now = hist.counts.copy()
    d = now - counts_before
    n = int(d.sum())
    if n == 0:
        return (float('nan'), float('nan'), 0), now
    p99, mx = hist.quantile([0.99, 1.0], d)
    return (float(p99), float(mx), n), now


class GcPauses:
    """Collections and their longest pause [s] (gc.callbacks), per generation, since reset."""

    def __init__(self):
        import gc
        self.reset()
        self._t0 = 0.0
        gc.callbacks.append(self._cb)

    def reset(self) -> None:
        self.count, self.max_pause = [0, 0, 0], 0.0

    def _cb(self, phase, info) -> None:
        if phase == 'start':
            self._t0 = time.perf_counter()
        else:
            self.count[info['generation']] += 1
            self.max_pause = max(self.max_pause, time.perf_counter() - self._t0)

    def text(self) -> str:
        return f'gc {"/".join(map(str, self.count))} max {self.max_pause * 1e3:.2f} ms'


def one_process(minutes: float, interval: float, workdir: Path, freeze: bool = True,
                force_mode: str | None = None, in_process: bool = True) -> None:
    """``in_process``: the recorder in the loop's process, as ``haptic-anfis sim --record`` runs
    it; False: in a process of its own (``sim --recorder-process``)."""
    import gc

    from haptic_anfis.bag.reader import recorded_summary
    from haptic_anfis.bag.topics import ALL_LOOP_TOPICS
    from haptic_anfis.session import open_graph
    from haptic_anfis.nodes.recorder import Recorder
    from haptic_anfis.realtime.processes import recorder_arguments
    from haptic_anfis.nodes.side_nodes import SideNodes, hold_until_recorded
    bag = workdir / 'one_process_bag'
    from rclpy.parameter import Parameter
    over = {'falcon_driver': [Parameter('force_mode', value=force_mode)]} if force_mode else None
    extra = [lambda ctx: Recorder(context=ctx, output=str(bag), topics=ALL_LOOP_TOPICS)] \
        if in_process else []
    g = open_graph(overrides=over, extra=extra)
    side = SideNodes({} if in_process else {'recorder': recorder_arguments(bag, ALL_LOOP_TOPICS)})
    try:
        side.start(300.0)
        if side and not hold_until_recorded(g, 300.0):
            raise RuntimeError('the recorder process did not subscribe within 300 s')
        if g.wait_ready(300.0) is None:
            raise RuntimeError('no force command within 300 s')
        st = g.driver.servo.stats
        st.reset()
        rec = g.extra[0] if in_process else None
        if not freeze:  # for comparison: what open_graph's gc.freeze() avoids
            gc.unfreeze()
        pauses = GcPauses()
        print(f'one process + recorder ({"in the same process" if in_process else "own process"}), '
              f'force_mode {g.driver.input.mode}, {minutes:g} min, '
              f'load {os.getloadavg()[0]:.2f}, gc '
              f'{"frozen after start" if freeze else "not frozen"}')
        print(HEADER + ', gc collections (gen 0/1/2) and longest pause, recorder chunks flushed '
              '/ pending')
        t0 = time.monotonic()
        ticks0 = misses0 = 0
        counts0 = st.latency_hist.counts.copy()
        tprev = t0
        while time.monotonic() - t0 < minutes * 60 - 1e-3:
            g.spin_for(min(interval, minutes * 60 - (time.monotonic() - t0)))
            now = time.monotonic()
            ticks, misses = st.ticks, st.deadline_misses
            lat, counts0 = interval_latency(st.latency_hist, counts0)
            rss = {'sim': rss_mb(), **{n: rss_mb(pid) for n, pid in side.pids.items()}}
            w = rec.writer.stats() if rec is not None else None
            print(row((now - t0) / 60, (ticks - ticks0) / (now - tprev), lat,
                      misses - misses0, dir_mb(bag), rss)
                  + f', {pauses.text()}'
                  + (f', chunks {w["chunks_flushed"]} pending {w["pending"]}' if w else ''),
                  flush=True)
            pauses.reset()
            ticks0, misses0, tprev = ticks, misses, now
        s = g.driver.summary()
        print(f'whole run: {s["rate_hz"]:.1f} Hz, p99 {s["latency_p99_ms"]:.3f} ms, max '
              f'{s["latency_max_ms"]:.3f} ms, {s["latency_next_tick_pct"]:.2f} % of the answers '
              f'taken at the next tick, misses {s["deadline_misses"]} of {s["ticks"]} '
              f'ticks, watchdog trips {s["watchdog_trips"]}')
    finally:
        g.shutdown()
        side.stop()
    done = rec.writer.stats() if in_process else recorded_summary(bag)
    print(f'bag {bag}: {dir_mb(bag):.1f} MB, recorded {done}', flush=True)


def multi_process(minutes: float, interval: float, workdir: Path,
                  force_mode: str | None = None, priority: int | None = None,
                  graph_priority: int | None = None, graph_pinning: str | None = None) -> None:
    """``priority``: the driver's ``servo_priority`` (None: its default, real-time where
    allowed); 0 runs the session as a user without real-time rights does (the servo and the
    graph under the normal scheduler: ``--graph-priority 0``). ``graph_priority``: launch's
    ``--graph-priority`` (None: as ``priority`` says); 0 with ``priority`` 50 is the session of
    a user whose servo rtkit raises while the graph stays under the normal scheduler."""
    import rclpy
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from rclpy.context import Context

    from haptic_anfis.realtime.processes import node_env
    from haptic_anfis import interfaces as ifc
    from haptic_anfis.nodes.runtime import LOOP_QOS, stamp_ns
    from haptic_anfis.nodes.executor import make_executor
    domain = 170 + os.getpid() % 40
    bag, out = workdir / 'multi_process_bag', workdir / 'launch.out'
    env = node_env(domain, localhost=True)
    env['PYTHONPATH'] = str(ROOT)
    driver = {k: v for k, v in (('force_mode', force_mode), ('servo_priority', priority))
              if v is not None}
    if driver:
        print('separate processes: falcon_driver '
              + ', '.join(f'{k} {v}' for k, v in driver.items()))
    driver['trace_seconds'] = 0.0   # every tick: the loop report covers the whole run
    f = workdir / 'driver.yaml'
    f.write_text('falcon_driver:\n  ros__parameters:\n'
                 + ''.join(f'    {k}: {v}\n' for k, v in driver.items()))
    params = ['--params-file', str(f)]
    if graph_priority is None and priority is not None and priority <= 0:
        graph_priority = 0  # no real-time rights: the graph has none either
    if graph_priority is not None:
        params += ['--graph-priority', str(graph_priority)]
    if graph_pinning is not None:
        params += ['--graph-pinning', graph_pinning]
    launch = subprocess.Popen(
        [sys.executable, '-m', 'haptic_anfis.cli', 'launch', '--nodes',
         'falcon_driver,contact_detector,force_server', '--domain-id', str(domain), '--localhost',
         '--record', str(bag), '--log-dir', str(workdir / 'logs'), *params],
        cwd=ROOT, env=env, stdout=out.open('w'), stderr=subprocess.STDOUT)
    ctx = Context()
    from rclpy.signals import SignalHandlerOptions
    # rclpy's handlers would only shut the context: Ctrl-C / SIGTERM must reach the finally
    # blocks (the launch stopped, the busy processes ended)
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('soak_observer', context=ctx)
    poses: list[int] = []
    lats: list[float] = []
    node.create_subscription(PoseStamped, ifc.TOPIC_POSE,
                             lambda m: poses.append(stamp_ns(m.header.stamp)), LOOP_QOS)
    node.create_subscription(WrenchStamped, ifc.TOPIC_COMMAND,
                             lambda m: lats.append((time.time_ns() - stamp_ns(m.header.stamp))
                                                   * 1e-9), LOOP_QOS)
    ex = make_executor(ctx)
    ex.add_node(node)
    try:
        end = time.monotonic() + 300
        while 'ready after' not in out.read_text():
            if launch.poll() is not None or time.monotonic() > end:
                raise RuntimeError('launch not ready:\n' + out.read_text()[-2000:])
            ex.spin_once(timeout_sec=0.1)
        pids = dict(re.findall(r'started (\w+) +pid (\d+)', out.read_text()))
        print(f'separate processes (launch --record), {minutes:g} min, load '
              f'{os.getloadavg()[0]:.2f}')
        print(HEADER)
        t0 = tprev = time.monotonic()
        p0 = l0 = 0
        while time.monotonic() - t0 < minutes * 60 - 1e-3:
            stop = min(tprev + interval, t0 + minutes * 60)
            while time.monotonic() < stop:
                ex.spin_once(timeout_sec=0.01)
            now = time.monotonic()
            pids.update(re.findall(r'node (\w+), pid (\d+)', out.read_text()))  # restarts
            st = np.asarray(poses[p0:], dtype=np.int64)
            gaps = int(np.sum(np.diff(st) > 2_000_000)) if len(st) > 1 else 0
            print(row((now - t0) / 60, len(st) / (now - tprev), np.asarray(lats[l0:]), gaps,
                      dir_mb(bag), {n: rss_mb(p) for n, p in pids.items()}), flush=True)
            p0, l0, tprev = len(poses), len(lats), now
    finally:
        stop_launch(launch, ex, node, ctx)
    # launch's loop report: the driver's own ticks (the rows above are what this observer got)
    lines = out.read_text().strip().splitlines()
    first = max((i for i, line in enumerate(lines) if line.startswith('loop (')),
                default=len(lines) - 1)
    print('\n'.join(lines[first:]))
    driver_log = workdir / 'logs' / 'falcon_driver.log'
    said = [line.split('servo thread: ', 1)[1]
            for line in (driver_log.read_text().splitlines() if driver_log.exists() else ())
            if 'servo thread: ' in line]
    print(f'servo thread: {said[0] if said else "not said"}')
    print(f'bag {bag}: {dir_mb(bag):.1f} MB', flush=True)


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--one-minutes', type=float, default=10.0,
                    help='minutes of the one-process run (0 = skip; default 10)')
    ap.add_argument('--multi-minutes', type=float, default=10.0,
                    help='minutes of the multi-process run (0 = skip; default 10)')
    ap.add_argument('--force-mode', choices=('zoh', 'local_model'), default=None,
                    help="the falcon driver's force_mode (default: its configured one)")
    ap.add_argument('--interval', type=float, default=60.0, help='seconds per row (default 60)')
    ap.add_argument('--recorder-process', action='store_true',
                    help='one process: the recorder in a process of its own (as haptic-anfis sim '
                         '--record --recorder-process; default: in the loop\'s process)')
    ap.add_argument('--no-freeze', action='store_true',
                    help='one process: undo the gc.freeze() done after start (for comparison)')
    ap.add_argument('--keep', metavar='DIR', default=None,
                    help='write the bags and logs here and keep them (default: a temporary '
                         'directory, removed)')
    ap.add_argument('--servo-priority', type=int, default=None, metavar='P',
                    help="separate processes: the driver's servo_priority (default: its "
                         'default, real-time where allowed; 0: as a user without real-time '
                         'rights, the graph under the normal scheduler too)')
    ap.add_argument('--graph-priority', type=int, default=None, metavar='P',
                    help="separate processes: launch's --graph-priority (default: 0 with "
                         '--servo-priority 0, else launch\'s default); 0 with --servo-priority 50 '
                         'is a user whose servo rtkit raises, the graph under the normal '
                         'scheduler')
    ap.add_argument('--graph-pinning', default=None, choices=('auto', 'on', 'off'),
                    help="separate processes: launch's --graph-pinning (default: launch's)")
    ap.add_argument('--busy', type=int, default=0, metavar='N',
                    help='N processes spinning on the CPU beside the runs (the load of other '
                         "programs, as bench_servo_load's --busy; default 0: a quiet machine)")
    ap.add_argument('--page', default='soak',
                    help='page name: docs/measurements/<page>.md (default soak)')
    return ap


def main() -> int:
    a = parser().parse_args()
    import signal
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))   # the finally blocks run
    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix='soak_'))
    work.mkdir(parents=True, exist_ok=True)
    print(f'soak: {os.cpu_count()} CPUs, load average {os.getloadavg()}'
          + (f'; {a.busy} busy processes spinning beside it' if a.busy else ''))
    print(account())
    try:
        with busy(a.busy):   # ended with the runs, also on an error
            if a.one_minutes > 0:
                one_process(a.one_minutes, a.interval, work, freeze=not a.no_freeze,
                            force_mode=a.force_mode, in_process=not a.recorder_process)
            if a.multi_minutes > 0:
                multi_process(a.multi_minutes, a.interval, work, force_mode=a.force_mode,
                              priority=a.servo_priority,
                              graph_priority=a.graph_priority, graph_pinning=a.graph_pinning)
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__, name=parser().parse_known_args()[0].page))
