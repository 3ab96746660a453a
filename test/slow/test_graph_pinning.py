"""Under the normal scheduler, each node on the haptic path is kept on one CPU (issue 32: beside
busy processes a thread of a node in its own session, woken on the CPU where the node had little
load, waited runnable longer than model_hold_time and the models expired mid-press)."""
from __future__ import annotations

import argparse
import os
import subprocess
import sys

import pytest

from haptic_anfis.realtime import processes
from haptic_anfis.session.spec import SessionSpec, add_session_arguments, spec_from_args

CPUS = sorted(os.sched_getaffinity(0))
two_cpus = pytest.mark.skipif(len(CPUS) < 2, reason='one CPU: nothing to choose')

#: a child with a second thread (as a node has its executor and DDS threads)
THREADED = ('import threading, time\n'
            'threading.Thread(target=time.sleep, args=(30,), daemon=True).start()\n'
            'print("up", flush=True)\n'
            'time.sleep(30)\n')


def _threaded() -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, '-c', THREADED], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == 'up'
    return p


def _affinities(pid: int) -> list[set[int]]:
    return [os.sched_getaffinity(int(t)) for t in os.listdir(f'/proc/{pid}/task')]


def test_round_robin_over_the_cpus_in_node_order():
    names = ['recorder', 'force_server', 'contact_detector', 'falcon_driver']
    assert processes.graph_cores(names, [0, 1]) == {
        'recorder': 0, 'force_server': 1, 'contact_detector': 0, 'falcon_driver': 1}
    assert processes.graph_cores(names, [2, 5, 7]) == {
        'recorder': 2, 'force_server': 5, 'contact_detector': 7, 'falcon_driver': 2}
    assert processes.graph_cores(names, [3]) == {}   # one CPU: nothing to choose
    assert processes.graph_cores([], [0, 1]) == {}


@two_cpus
def test_keep_on_cpu_moves_every_thread():
    p = _threaded()
    try:
        assert len(os.listdir(f'/proc/{p.pid}/task')) >= 2
        assert processes.keep_on_cpu(p.pid, CPUS[-1]) == f'threads kept on CPU {CPUS[-1]}'
        assert _affinities(p.pid) == [{CPUS[-1]}] * len(_affinities(p.pid))
    finally:
        p.kill()
        p.wait()
    # an ended process: said, not raised
    assert processes.keep_on_cpu(p.pid, CPUS[0]) == 'no thread to keep on a CPU'


def test_a_refusal_is_said_in_words():
    p = _threaded()
    try:
        what = processes.keep_on_cpu(p.pid, 10_000)   # no such CPU
        assert what.startswith('threads not kept on CPU 10000 (OSError: ')
    finally:
        p.kill()
        p.wait()


@two_cpus
def test_supervisor_pins_the_loop_nodes_left_normal_never_a_view_node(monkeypatch):
    """Real-time priority refused (or 0): the haptic-path nodes are kept on their CPU, once per
    start, and say so; the view nodes are left alone."""
    monkeypatch.setattr(processes, 'set_graph_priority',
                        lambda prio, pid=None: 'normal scheduler: SCHED_FIFO 10 refused (test)')
    procs = {n: _threaded() for n in ('force_server', 'contact_detector', 'web_view')}
    try:
        sup = processes.Supervisor({})
        sup.procs.update(procs)
        sup.cores = processes.graph_cores(['force_server', 'contact_detector'], CPUS[:2])
        done = sup.raise_priority(10, list(procs))
        assert done == {
            'force_server': f'normal scheduler: SCHED_FIFO 10 refused (test); threads kept on '
                            f'CPU {CPUS[0]}',
            'contact_detector': f'normal scheduler: SCHED_FIFO 10 refused (test); threads kept '
                                f'on CPU {CPUS[1]}'}
        assert set(map(frozenset, _affinities(procs['force_server'].pid))) == {
            frozenset({CPUS[0]})}
        assert set(map(frozenset, _affinities(procs['contact_detector'].pid))) == {
            frozenset({CPUS[1]})}
        assert _affinities(procs['web_view'].pid)[0] == set(CPUS)
        assert sup.raise_priority(10, list(procs)) == {}   # once per start
    finally:
        for p in procs.values():
            p.kill()
            p.wait()


@two_cpus
def test_graph_priority_zero_pins_and_pinning_off_does_not():
    procs = {n: _threaded() for n in ('force_server', 'recorder')}
    try:
        sup = processes.Supervisor({})
        sup.procs.update(procs)
        sup.cores = {'force_server': CPUS[1]}   # the recorder: pinning off for it
        done = sup.raise_priority(0, list(procs))
        assert done == {'force_server': 'normal scheduler (graph priority 0); threads kept on '
                                        f'CPU {CPUS[1]}'}
        assert _affinities(procs['recorder'].pid)[0] == set(CPUS)
    finally:
        for p in procs.values():
            p.kill()
            p.wait()


#: a falcon driver stand-in: it forks a servo process whose main thread is named as the tick
#: worker is, real-time when asked ('rt'), as the driver's servo process is
DRIVER = ('import ctypes, os, sys, time\n'
          'if os.fork() == 0:\n'
          '    ctypes.CDLL(None).prctl(15, b"servo-tick0", 0, 0, 0)\n'
          '    if sys.argv[1] == "rt":\n'
          '        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(3))\n'
          '    print("up", flush=True)\n'
          '    time.sleep(30)\n'
          '    os._exit(0)\n'
          'time.sleep(30)\n')


def _driver(how: str) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, '-c', DRIVER, how], stdout=subprocess.PIPE, text=True,
                         start_new_session=True)
    p.own_session = True
    assert p.stdout.readline().strip() == 'up'
    return p


def _rt_allowed() -> bool:
    r = subprocess.run([sys.executable, '-c', 'import os; os.sched_setscheduler(0, '
                        'os.SCHED_FIFO, os.sched_param(3))'], capture_output=True)
    return r.returncode == 0


def _stop(procs) -> None:
    """Kill the stand-ins, a driver with its servo process (the driver's session)."""
    for p in procs:
        if getattr(p, 'own_session', False):
            os.killpg(p.pid, 9)
        else:
            p.kill()
        p.wait()


def test_servo_realtime_reads_the_servo_process_threads():
    """Found in the driver's child (its servo process) by thread name; None where the driver
    has no servo thread (not started)."""
    plain = _threaded()
    normal = _driver('normal')
    procs = [plain, normal]
    try:
        assert processes.servo_realtime(plain.pid) is None
        assert processes.servo_realtime(normal.pid) is False
        if _rt_allowed():
            procs.append(rt := _driver('rt'))
            assert processes.servo_realtime(rt.pid) is True
    finally:
        _stop(procs)


@pytest.fixture
def graph():
    """A supervisor with a driver stand-in (its servo real-time or not) and a force server,
    each with its CPU; ``graph(how, pinning)`` -> (supervisor, procs). Killed after the test."""
    made = []

    def make(how: str, pinning: str = 'auto'):
        procs = {'falcon_driver': _driver(how), 'force_server': _threaded()}
        made.extend(procs.values())
        sup = processes.Supervisor({})
        sup.procs.update(procs)
        sup.pinning = pinning
        sup.cores = processes.graph_cores(list(procs), CPUS[:2])
        return sup, procs
    yield make
    _stop(made)


@two_cpus
def test_nodes_are_left_free_when_the_servo_is_not_real_time_either(graph):
    """Graph and servo both under the normal scheduler: pinned nodes took their CPU's share from
    the servo's tick workers (more periods lost), so they are left free, and the words say why."""
    sup, procs = graph('normal')
    assert sup.raise_priority(0, list(procs)) == {
        n: 'normal scheduler (graph priority 0); threads left free: the servo loop is under the '
           'normal scheduler too' for n in procs}
    assert _affinities(procs['force_server'].pid)[0] == set(CPUS)


@two_cpus
def test_pinning_on_pins_whatever_the_servo(graph):
    sup, procs = graph('normal', pinning='on')
    assert sup.raise_priority(0, list(procs))['force_server'] == (
        f'normal scheduler (graph priority 0); threads kept on CPU {CPUS[1]}')


@two_cpus
@pytest.mark.skipif(not _rt_allowed(), reason='SCHED_FIFO refused here')
def test_nodes_are_pinned_when_the_servo_is_real_time(graph):
    sup, procs = graph('rt')
    assert sup.raise_priority(0, list(procs))['force_server'] == (
        f'normal scheduler (graph priority 0); threads kept on CPU {CPUS[1]}')
    assert set(map(frozenset, _affinities(procs['force_server'].pid))) == {frozenset({CPUS[1]})}


def test_launch_option():
    """auto by default in launch (the recommended configuration: pinned where the servo is
    real-time); on / off force it; sim and exam run have one process for the graph and no such
    option."""
    p = argparse.ArgumentParser()
    add_session_arguments(p, 'launch')
    assert SessionSpec().graph_pinning == 'auto'
    assert spec_from_args(p.parse_args([]), 'launch').graph_pinning == 'auto'
    for how in ('on', 'off'):
        assert spec_from_args(p.parse_args(['--graph-pinning', how]), 'launch'
                              ).graph_pinning == how
    with pytest.raises(SystemExit):
        p.parse_args(['--graph-pinning', 'yes'])
    q = argparse.ArgumentParser()
    add_session_arguments(q, 'sim')
    with pytest.raises(SystemExit):
        q.parse_args(['--graph-pinning', 'on'])
