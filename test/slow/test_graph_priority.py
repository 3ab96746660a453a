"""The nodes that make the local models run real-time once ready, below the servo thread, the
view nodes never (issue 32: a busy machine starved them and the models expired mid-press).

Real-time scheduling needs CAP_SYS_NICE or an rtprio limit: the tests that change a policy run
it in child processes (never this test process) and skip where it is refused.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from haptic_anfis.realtime import processes
from haptic_anfis.session.spec import SessionError, SessionSpec, spec_from_args

PRIO = 3  # below anything a real session uses, so a run beside one changes nothing there


def _allowed() -> bool:
    code = ('import os\n'
            f'os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param({PRIO}))')
    return subprocess.run([sys.executable, '-c', code], capture_output=True).returncode == 0


needs_rt = pytest.mark.skipif(not _allowed(), reason='SCHED_FIFO refused here')


def _run(code: str) -> str:
    r = subprocess.run([sys.executable, '-c', textwrap.dedent(code)], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_default_and_range():
    """On by default (the recommended configuration) at the documented priority, below the
    driver's servo thread (50); a priority the servo thread could not stay above is refused in
    one line naming the option."""
    assert SessionSpec().graph_priority == processes.GRAPH_PRIORITY == 10
    import argparse

    from haptic_anfis.session.spec import add_session_arguments
    for cmd in ('sim', 'launch', 'exam'):
        p = argparse.ArgumentParser()
        add_session_arguments(p, cmd)
        assert spec_from_args(p.parse_args([]), cmd).graph_priority == 10
        assert spec_from_args(p.parse_args(['--graph-priority', '0']), cmd).graph_priority == 0
    for bad in (-1, 99):
        with pytest.raises(SessionError, match='--graph-priority: expected 0'):
            SessionSpec(graph_priority=bad).check(check_parameters=False)


def test_priority_zero_changes_nothing():
    assert processes.set_graph_priority(0) == 'normal scheduler (graph priority 0)'
    assert processes.leave_realtime() == 0  # nothing real-time to leave
    assert os.sched_getscheduler(0) == os.SCHED_OTHER


@needs_rt
def test_every_thread_raised_but_one_already_above_then_cleared():
    """All threads of the process, also those started before; a thread already real-time above
    (the servo thread) keeps its priority; threads started after inherit it; clearing returns
    the raised ones to the normal scheduler and leaves the servo thread alone."""
    out = _run(f'''
        import os, threading
        from haptic_anfis.realtime.scheduling import name_thread
        from haptic_anfis.realtime.processes import set_graph_priority, leave_realtime
        ev, seen = threading.Event(), {{}}
        started = {{k: threading.Event() for k in ('servo', 'worker', 'late')}}
        def servo():
            name_thread('servo-tick0')
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param({PRIO + 2}))
            seen['servo'] = threading.get_native_id()
            started['servo'].set()
            ev.wait()
        def worker():
            seen['worker'] = threading.get_native_id()
            started['worker'].set()
            ev.wait()
        def late():
            seen['late'] = pol(0)
            started['late'].set()
            ev.wait()
        def pol(t): return (os.sched_getscheduler(t), os.sched_getparam(t).sched_priority)
        for f in (servo, worker): threading.Thread(target=f).start()
        started['servo'].wait(); started['worker'].wait()
        print(set_graph_priority({PRIO}))
        threading.Thread(target=late).start()
        started['late'].wait()
        print(pol(0), pol(seen['servo']), pol(seen['worker']), seen['late'])
        leave_realtime()
        print(pol(0), pol(seen['servo']), pol(seen['worker']))
        ev.set()
    ''').splitlines()
    fifo, other = os.SCHED_FIFO, os.SCHED_OTHER
    assert out[0] == f'SCHED_FIFO priority {PRIO}'
    assert out[1] == ' '.join(map(str, ((fifo, PRIO), (fifo, PRIO + 2), (fifo, PRIO),
                                        (fifo, PRIO))))
    assert out[2] == ' '.join(map(str, ((other, 0), (fifo, PRIO + 2), (other, 0))))


@needs_rt
def test_a_node_started_by_a_realtime_process_starts_normal():
    """sim's graph is real-time once ready: a node it starts (a view node, the recorder in its
    own process) must not inherit that."""
    out = _run(f'''
        import functools, os, subprocess, sys
        from haptic_anfis.realtime import processes
        processes.set_graph_priority({PRIO})
        child = [sys.executable, '-c', 'import os; print(os.sched_getscheduler(0))']
        print(subprocess.run(child, capture_output=True, text=True,
                             preexec_fn=functools.partial(processes._in_child, False, 0)
                             if processes._realtime() else None).stdout.strip())
    ''')
    assert out.strip() == str(os.SCHED_OTHER)


@needs_rt
def test_supervisor_raises_the_loop_nodes_once_and_never_a_view_node(monkeypatch):
    procs = {n: subprocess.Popen(['sleep', '30']) for n in ('force_server', 'web_view',
                                                             'visualizer')}
    try:
        sup = processes.Supervisor({})
        sup.procs.update(procs)
        done = sup.raise_priority(PRIO, list(procs))
        assert done == {'force_server': f'SCHED_FIFO priority {PRIO}'}
        assert os.sched_getscheduler(procs['force_server'].pid) == os.SCHED_FIFO
        assert os.sched_getscheduler(procs['web_view'].pid) == os.SCHED_OTHER
        assert os.sched_getscheduler(procs['visualizer'].pid) == os.SCHED_OTHER
        assert sup.raise_priority(PRIO, list(procs)) == {}  # once per start
        assert sup.raise_priority(0, ['force_server']) == {}
    finally:
        for p in procs.values():
            p.kill()
            p.wait()


def test_refused_fifo_asks_rtkit_for_the_haptic_path_threads(monkeypatch):
    """Without the right to SCHED_FIFO (a trainee's account) the graph's threads that carry the
    haptic path ask rtkit for SCHED_RR, with the soft run-time limit below rtkit's; threads rtkit
    refused are said; rtkit refusing them all, or absent, is the refusal's line with both
    reasons. Fakes only: no policy changes."""
    from haptic_anfis.realtime import rtkit
    from haptic_anfis.realtime.rtkit import RealtimeKitError

    def refuse(*a):
        raise PermissionError(1, 'Operation not permitted')
    monkeypatch.setattr(os, 'sched_setscheduler', refuse)
    monkeypatch.setattr(processes, '_threads', lambda pid=None: [7, 8, 9, 10])
    monkeypatch.setattr(processes, 'haptic_path_threads', lambda pid=None: [7, 8, 9])
    asked = []

    def kit(priority, tids, pid, soft_share):
        asked.append((priority, list(tids), pid, soft_share))
        return min(priority, 20), answer
    monkeypatch.setattr(rtkit, 'make_threads_realtime', kit)
    answer = {}
    assert processes.set_graph_priority(10, 4321) == (
        'SCHED_RR priority 10 from rtkit for 3 of its threads (executor, DDS receive, servo '
        'bridge), in place of SCHED_FIFO 10')
    assert asked == [(10, [7, 8, 9], 4321, processes.RTTIME_SOFT_SHARE)]
    answer = {8: 'rtkit: org.freedesktop.DBus.Error.Failed: burst'}
    assert processes.set_graph_priority(10, 4321).endswith(
        'for 2 of its threads (executor, DDS receive, servo bridge), in place of SCHED_FIFO 10; '
        '1 not raised (rtkit: org.freedesktop.DBus.Error.Failed: burst)')
    answer = dict.fromkeys((7, 8, 9), 'rtkit: org.freedesktop.DBus.Error.Failed: burst')
    said = processes.set_graph_priority(10, 4321)
    assert said.startswith('normal scheduler: SCHED_FIFO 10 refused (Operation not permitted; '
                           'rtkit: org.freedesktop.DBus.Error.Failed: burst)')

    def absent(*a, **k):
        raise RealtimeKitError('rtkit: no rtkit-daemon on this machine')
    monkeypatch.setattr(rtkit, 'make_threads_realtime', absent)
    assert 'rtkit: no rtkit-daemon on this machine)' in processes.set_graph_priority(10, 4321)


def test_haptic_path_threads_are_the_main_one_and_those_named_for_it():
    """The executor (the main thread), Fast DDS's receive threads and the servo bridge; not a
    thread asleep for good under another name."""
    import threading

    from haptic_anfis.realtime.scheduling import name_thread
    named, go = {}, threading.Event()

    def run(name):
        name_thread(name)
        named[name] = threading.get_native_id()
        go.wait()
    threads = [threading.Thread(target=run, args=(n,)) for n in ('dds.udp.7411', 'servo-bridge',
                                                                 'openblas-idle')]
    for t in threads:
        t.start()
    try:
        while len(named) < 3:
            threading.Event().wait(0.01)
        got = processes.haptic_path_threads()
    finally:
        go.set()
        for t in threads:
            t.join()
    assert os.getpid() in got
    assert named['dds.udp.7411'] in got and named['servo-bridge'] in got
    assert named['openblas-idle'] not in got


@needs_rt
def test_a_thread_over_the_soft_run_time_limit_goes_normal_and_the_process_lives(tmp_path):
    """SIGXCPU (a thread at real-time priority ran the soft RLIMIT_RTTIME without blocking): the
    process's real-time threads go back to the normal scheduler, one line says so, and the
    node is not ended (SIGXCPU's default) nor killed at the hard limit. With no compiled
    bytecode at hand (a fresh install), so that the handler's 100 ms are not spent importing."""
    r = subprocess.run([sys.executable, '-X', f'pycache_prefix={tmp_path}', '-c',
                        textwrap.dedent(f'''
        import os, resource, time
        from haptic_anfis.realtime.processes import guard_realtime_time
        guard_realtime_time()
        resource.setrlimit(resource.RLIMIT_RTTIME, (100_000, 200_000))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param({PRIO}))
        t = time.process_time()
        while time.process_time() - t < 0.3:
            pass
        print(os.sched_getscheduler(0), resource.getrlimit(resource.RLIMIT_RTTIME))
    ''')], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[0] == str(os.SCHED_OTHER)
    assert r.stdout.strip().endswith('(100000, 200000)')  # the soft limit set again
    assert ('a thread ran 100 ms at real-time priority without blocking (RLIMIT_RTTIME): 1 '
            'threads of this process back to the normal scheduler') in r.stderr


@needs_rt
def test_leaving_real_time_keeps_the_servo_threads_and_lets_a_long_close_run():
    """A node's shutdown (run_node, before close()) takes every real-time thread of its process
    but the servo's back to the normal scheduler: a close that then computes past the hard
    RLIMIT_RTTIME (the driver writing an hour's trace) is not SIGKILLed for it."""
    r = subprocess.run([sys.executable, '-c', textwrap.dedent(f'''
        import os, resource, threading, time
        from haptic_anfis.realtime.scheduling import name_thread, realtime_priority
        from haptic_anfis.realtime.processes import leave_realtime
        resource.setrlimit(resource.RLIMIT_RTTIME, (100_000, 200_000))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param({PRIO}))
        tid, go = [], threading.Event()
        def servo():
            name_thread('servo-tick0')
            tid.append(threading.get_native_id())
            go.wait()
        th = threading.Thread(target=servo)
        th.start()
        while not tid:
            time.sleep(0.01)
        n = leave_realtime()
        t = time.process_time()
        while time.process_time() - t < 0.3:   # past the hard limit, at the normal scheduler
            pass
        print(n, os.sched_getscheduler(0), realtime_priority(tid[0]))
        go.set()
        th.join()
    ''')], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, (r.returncode, r.stderr)
    assert r.stdout.split() == ['1', str(os.SCHED_OTHER), str(PRIO)]


def test_sim_runs_its_graph_in_a_session_of_its_own_and_stops_on_ctrl_c(tmp_path):
    """``haptic-anfis sim`` from a command line re-runs itself in a session of its own (its
    CPU share no longer split with the terminal's other jobs); Ctrl-C (SIGINT) at the
    terminal's process is passed on: the graph stops cleanly, says so, and nothing is left."""
    import signal
    import time

    from haptic_anfis.realtime.processes import OWN_SESSION
    env = {k: v for k, v in os.environ.items() if k != OWN_SESSION}
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    p = subprocess.Popen([sys.executable, '-m', 'haptic_anfis.cli', 'sim', '--duration', '120',
                          '--no-viz', '--json'], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    lines = []
    try:
        for line in p.stdout:
            lines.append(line)
            if line.startswith('ready after'):
                break
        time.sleep(1.0)
        p.send_signal(signal.SIGINT)
        out, _ = p.communicate(timeout=120)
    finally:
        p.kill()
    lines += out.splitlines()
    assert p.returncode == 0, ''.join(lines)[-2000:]
    assert any(line.startswith('interrupted') for line in lines)
    import json
    j = json.loads([line for line in lines if line.startswith('{')][-1])
    assert j['own_session'] is True
    assert j['rate_hz'] > 0
    left = subprocess.run(['pgrep', '-f', 'haptic_anfis.cli sim --duration 120 --no-viz'],
                          capture_output=True)
    assert left.returncode == 1, left.stdout  # the re-run has ended with its parent
