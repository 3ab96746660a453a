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

from haptic_anfis.nodes import processes
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
    processes.clear_graph_priority(0)
    assert os.sched_getscheduler(0) == os.SCHED_OTHER


@needs_rt
def test_every_thread_raised_but_one_already_above_then_cleared():
    """All threads of the process, also those started before; a thread already real-time above
    (the servo thread) keeps its priority; threads started after inherit it; clearing returns
    the raised ones to the normal scheduler and leaves the servo thread alone."""
    out = _run(f'''
        import os, threading
        from haptic_anfis.nodes.processes import set_graph_priority, clear_graph_priority
        ev, seen = threading.Event(), {{}}
        started = {{k: threading.Event() for k in ('servo', 'worker', 'late')}}
        def servo():
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
        clear_graph_priority({PRIO})
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
        from haptic_anfis.nodes import processes
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


def test_sim_runs_its_graph_in_a_session_of_its_own_and_stops_on_ctrl_c(tmp_path):
    """``haptic-anfis sim`` from a command line re-runs itself in a session of its own (its
    CPU share no longer split with the terminal's other jobs); Ctrl-C (SIGINT) at the
    terminal's process is passed on: the graph stops cleanly, says so, and nothing is left."""
    import signal
    import time

    from haptic_anfis.nodes.processes import OWN_SESSION
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
