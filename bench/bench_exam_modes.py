"""``exam run`` in the driver's force modes and process layouts, and the force's return after a
force-server respawn (issue 26.4). Printed and written to docs/measurements/exam_modes.md; never
asserted (timings under load).

1. ``haptic-anfis exam run --trainee systematic --json`` with force_mode zoh / local_model and the
   examiner in the loop's process (``--in-process``) or its own (the default, sim's layout):
   deep coverage, hits / false marks, verdict, the heat map's rate (the examiner promises 5 Hz:
   heat maps published / session seconds in the loop's process, heat maps received per second in
   the exam's process with the examiner in its own), the contact samples the examiner lost, the
   deepest probe depth, the wall time.
2. ``haptic-anfis launch --nodes falcon_driver,contact_detector,force_server`` (sim backend, the
   palpation script, default force_mode): the force server is killed (SIGKILL) ``--kills`` times
   while the probe presses; per kill, the seconds until the launch restarted it and until force
   commands (``falcon/servo_cf``) came back.

``--busy N`` runs the exams beside N processes spinning on the CPU, ``--beside-tests`` beside
the project's test suite (what ``make test`` runs, restarted when it ends), ``--view`` with the
trainee's screen (``exam run --view``) and a headless chromium on it: issue 32.5, the exam passes
under the servo benchmark's load. ``--servo-priorities 50,0`` runs each exam with the driver's
servo at each priority (0: the normal scheduler, the graph's nodes too); ``--force-modes`` picks
the modes, ``--page`` the page.

Run: ``.venv/bin/python bench/bench_exam_modes.py [--runs N] [--kills N] [--busy N]
[--beside-tests] [--view] [--servo-priorities 50,0] [--force-modes local_model]
[--page exam_modes]``
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from harness import TestSuite, browser_when_up, busy, stop_launch, write_page  # noqa: E402

MODES = (('zoh', True), ('local_model', True), ('zoh', False), ('local_model', False))


def env(domain: int) -> dict:
    e = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
             PYTHONPATH=str(ROOT))
    e.setdefault('AMENT_PREFIX_PATH', str(Path(sys.executable).parents[1]))
    return e


def exam(mode: str, in_process: bool, domain: int, priority: int | None = None,
         view: bool = False) -> dict:
    """One ``exam run --trainee systematic --json``; ``priority``: the driver's servo_priority
    (None: its default; 0 also puts the graph's nodes under the normal scheduler); ``view``:
    with the trainee's screen and a headless chromium on it."""
    cmd = [sys.executable, '-m', 'haptic_anfis.cli', 'exam', 'run', '--json', '--force-mode', mode]
    if in_process:
        cmd.append('--in-process')
    work = Path(tempfile.mkdtemp(prefix='bench-exam-'))
    if priority is not None:
        pf = work / 'driver.yaml'
        pf.write_text(f'falcon_driver:\n  ros__parameters:\n    servo_priority: {priority}\n')
        cmd += ['--params-file', str(pf)] + (['--graph-priority', '0'] if priority == 0 else [])
    stop = threading.Event()
    if view:
        from haptic_anfis.view.browser import free_port
        port = free_port()
        cmd += ['--view', '--view-port', str(port), '--view-hold', '0']
        browser = browser_when_up(port, stop)
    load0 = os.getloadavg()[0]
    t0 = time.monotonic()
    try:
        p = subprocess.run(cmd, cwd=ROOT, env=env(domain), capture_output=True, text=True,
                           timeout=900)
    finally:
        stop.set()
        if view:
            browser.join(timeout=60)
        shutil.rmtree(work, ignore_errors=True)
    wall = time.monotonic() - t0
    head = {'mode': mode, 'in_process': in_process, 'priority': priority, 'view': view,
            'browser': view and browser.started is not None}
    try:   # the report's line (with --view the debrief's address follows it)
        r = json.loads(next(ln for ln in reversed(p.stdout.splitlines()) if ln.startswith('{')))
    except (StopIteration, ValueError):
        return {**head, 'error': (p.stdout + p.stderr)[-1500:], 'wall_s': wall, 'load': load0}
    hz = r.get('heat_map_hz') or (r['heat_maps_published'] / r['duration_s']
                                  if r['duration_s'] else 0.0)
    return {**head, 'deep': r['coverage_pct']['deep'],
            'hits': r['hits'], 'misses': r['misses'], 'false': r['false_marks'],
            'verdict': r['verdict'], 'heat_hz': hz, 'lost': r.get('examiner_lost_contacts'),
            'max_depth_mm': r['max_depth_mm'], 'contact_samples': r['samples']['contact'],
            'duration_s': r['duration_s'], 'wall_s': wall, 'load': load0}


def respawn(kills: int, domain: int) -> list[dict]:
    """Kill the launched force server ``kills`` times; seconds until restarted / force back."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.context import Context

    from haptic_anfis import interfaces as ifc
    from haptic_anfis.nodes.runtime import LOOP_QOS
    from haptic_anfis.nodes.executor import make_executor
    work = Path(tempfile.mkdtemp(prefix='haptic-anfis-respawn-'))
    out = work / 'launch.out'
    launch = subprocess.Popen(
        [sys.executable, '-m', 'haptic_anfis.cli', 'launch', '--nodes',
         'falcon_driver,contact_detector,force_server', '--domain-id', str(domain), '--localhost',
         '--max-restarts', str(kills + 1), '--log-dir', str(work / 'logs')],
        cwd=ROOT, env=env(domain), stdout=out.open('w'), stderr=subprocess.STDOUT)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node('respawn_observer', context=ctx)
    arrivals: list[tuple[float, float]] = []   # (monotonic, |F|)
    node.create_subscription(
        WrenchStamped, ifc.TOPIC_COMMAND,
        lambda m: arrivals.append((time.monotonic(), abs(m.wrench.force.x)
                                   + abs(m.wrench.force.y) + abs(m.wrench.force.z))), LOOP_QOS)
    ex = make_executor(ctx)
    ex.add_node(node)
    rows = []

    def spin(seconds: float, until=None) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
            if until is not None and until():
                return True
        return False
    try:
        end = time.monotonic() + 300
        while 'ready after' not in out.read_text():
            if launch.poll() is not None or time.monotonic() > end:
                raise RuntimeError('launch not ready:\n' + out.read_text()[-2000:])
            spin(0.1)
        for k in range(kills):
            # wait for force commands with force (the probe pressing)
            n0 = len(arrivals)
            if not spin(60, lambda: any(f > 0.5 for _, f in arrivals[n0:])):
                rows.append({'kill': k + 1, 'error': 'no force before the kill'})
                continue
            pid = int(re.findall(r'(?:started force_server +pid|node force_server, pid) (\d+)',
                                 out.read_text())[-1])
            text0 = out.read_text()
            n_restarted = text0.count('restarted, node force_server')
            t_kill = time.monotonic()
            os.kill(pid, signal.SIGKILL)
            n1 = len(arrivals)
            t_restart = None
            resumed = spin(120, lambda: any(t > t_kill + 0.05 for t, _ in arrivals[n1:]))
            t_back = next((t for t, _ in arrivals[n1:] if t > t_kill + 0.05), None)
            spin(0.5)
            if out.read_text().count('restarted, node force_server') > n_restarted:
                m = re.findall(r'session: event restarted, t ([\d.]+), node force_server',
                               out.read_text())
                t_restart = m[-1] if m else None
            rows.append({'kill': k + 1, 'resumed': resumed,
                         'force_back_s': None if t_back is None else t_back - t_kill,
                         'restart_event_t': t_restart, 'load': os.getloadavg()[0]})
            print(f"kill {k + 1}: force commands back after "
                  f"{rows[-1]['force_back_s'] if t_back is not None else 'never (120 s)'} s, "
                  f"load {os.getloadavg()[0]:.1f}", flush=True)
            spin(10)   # let it settle before the next kill
    finally:
        stop_launch(launch, ex, node, ctx)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--runs', type=int, default=1, help='exams per mode and layout')
    ap.add_argument('--kills', type=int, default=3, help='force-server kills')
    ap.add_argument('--skip-exams', action='store_true')
    ap.add_argument('--busy', type=int, default=0,
                    help='processes spinning on the CPU beside every exam (default 0)')
    ap.add_argument('--beside-tests', action='store_true',
                    help="the project's test suite (python -m pytest test) running beside "
                         'every exam')
    ap.add_argument('--view', action='store_true',
                    help="the trainee's screen too: exam run --view and a headless chromium on it")
    ap.add_argument('--servo-priorities', default='',
                    help="comma-separated servo_priority values to run each exam with (0: the "
                         "normal scheduler, the graph's too; default: the driver's default)")
    ap.add_argument('--examiner', default='loop,own',
                    help="comma-separated: where the examiner runs, the loop's process (loop, "
                         '--in-process) or its own (own, the default of exam run); default both')
    ap.add_argument('--force-modes', default='zoh,local_model',
                    help='comma-separated force modes to run (default zoh,local_model)')
    ap.add_argument('--page', default='exam_modes',
                    help='page name: docs/measurements/<page>.md (default exam_modes)')
    a = ap.parse_args()
    layouts = {'loop': True, 'own': False}
    modes = [m for m in MODES if m[0] in a.force_modes.split(',')
             and m[1] in {layouts[w] for w in a.examiner.split(',')}]
    domain = 150 + os.getpid() % 40
    prios = [int(x) for x in a.servo_priorities.split(',')] if a.servo_priorities else [None]
    if a.view:
        from haptic_anfis.view.browser import chromium
        if chromium() is None:   # a row "with the view" measured without a browser: false
            raise SystemExit('bench_exam_modes: --view: no chromium on this machine (Debian: '
                             'apt-get install chromium, as .ci/run does); nothing measured')
    rows = []
    suite = TestSuite() if a.beside_tests else None
    try:
        for _ in range(0 if a.skip_exams else a.runs):
            for prio in prios:
                for mode, inproc in modes:
                    if suite is not None:
                        suite.ensure()
                        time.sleep(20.0 if suite.starts == 1 and not rows else 0.0)  # collecting
                    with busy(a.busy):
                        r = exam(mode, inproc, domain, prio, a.view)
                    rows.append(r)
                    print(json.dumps(r), flush=True)
    finally:
        if suite is not None:
            suite.stop()
    kills = respawn(a.kills, domain) if a.kills else []
    lines = ['`exam run --trainee systematic` (default case) per force mode and examiner process; '
             '"heat map" = its rate [Hz] (the examiner promises 5 Hz); "lost" = contact samples '
             'published that the side examiner\'s report does not hold; load = 1-minute load '
             'average at the start'
             + (f'; {a.busy} processes spinning on the CPU beside every exam' if a.busy else '')
             + ('; the test suite (`python -m pytest test`) running beside every exam'
                if a.beside_tests else '')
             + ("; the trainee's screen (`exam run --view`) with a headless chromium on it "
                '(software WebGL, a session of its own)' if a.view else '')
             + '; servo: the driver\'s servo_priority (0: the normal scheduler for the servo and '
             'the graph; default: its default, real-time where allowed).', '',
             '| force mode | examiner | servo | deep coverage % | hits / misses / false | verdict | '
             'heat map [Hz] | lost | max depth [mm] | contact samples | wall [s] | load |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        where = 'loop process' if r['in_process'] else 'own process'
        where += f" | {'default' if r['priority'] is None else r['priority']}"
        if r['view'] and not r['browser']:
            where += ' (no browser: the page never answered)'
        if 'error' in r:
            lines.append(f"| {r['mode']} | {where} | failed: {r['error'][-120:]!r} | | | | | | | "
                         f"{r['wall_s']:.0f} | {r['load']:.1f} |")
            continue
        lines.append(f"| {r['mode']} | {where} | {r['deep']:.1f} | {r['hits']} / {r['misses']} / "
                     f"{r['false']} | {r['verdict']} | {r['heat_hz']:.1f} | "
                     f"{'' if r['lost'] is None else r['lost']} | {r['max_depth_mm']:.1f} | "
                     f"{r['contact_samples']} | {r['wall_s']:.0f} | {r['load']:.1f} |")
    if kills:
        lines += ['', '`launch --nodes falcon_driver,contact_detector,force_server` (sim, '
                  'default force_mode): the force server killed with SIGKILL while the probe '
                  'pressed; seconds until force commands came back.', '',
                  '| kill | force commands back after [s] | load |', '|---|---|---|']
        for r in kills:
            if 'error' in r:
                lines.append(f"| {r['kill']} | {r['error']} | |")
            else:
                b = r['force_back_s']
                lines.append(f"| {r['kill']} | {'not within 120 s' if b is None else f'{b:.1f}'}"
                             f" | {r['load']:.1f} |")
    table = '\n'.join(lines)
    print(table)
    write_page(a.page, 'Exam in each force mode and process layout'
               + (f', beside {a.busy} busy processes' if a.busy else '')
               + (', beside the test suite' if a.beside_tests else '')
               + (', with the view' if a.view else '')
               + ('; force after a respawn' if kills else ''),
               table, command=('.venv/bin/python bench/bench_exam_modes.py '
                               + ' '.join(sys.argv[1:])).strip())


if __name__ == '__main__':
    main()
