"""Nodes off the haptic loop yield the CPU in a way the scheduler honours (issue 32).

With autogroups (on by default on many desktop kernels) the CPU is shared fairly between sessions
first; a node started in a session of its own with only ``nice`` lowered would compete with the
loop's session at full weight. :func:`yield_cpu` lowers its session's weight too.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from haptic_anfis.nodes import processes

AUTOGROUP = Path('/proc/self/autogroup')

# A child that reports its nice value and its session's autogroup nice after yield_cpu(7).
CHILD = ('import os, sys; from haptic_anfis.nodes.processes import yield_cpu; '
         'yield_cpu(int(sys.argv[1])); '
         'ag = open("/proc/self/autogroup").read().split() if os.path.exists("/proc/self/autogroup") '
         'else ["-", "nice", "none"]; print(os.getpriority(os.PRIO_PROCESS, 0), ag[-1])')


def _run(nice: int, own_session: bool) -> tuple[int, str]:
    r = subprocess.run([sys.executable, '-c', CHILD, str(nice)], capture_output=True, text=True,
                       start_new_session=own_session, check=True, timeout=60)
    p, ag = r.stdout.split()
    return int(p), ag


def _own_autogroup_nice() -> str:
    return AUTOGROUP.read_text().split()[-1]


def test_a_session_leader_lowers_its_session_too():
    base = os.getpriority(os.PRIO_PROCESS, 0)
    prio, ag = _run(7, own_session=True)
    assert prio == min(base + 7, 19)
    if not AUTOGROUP.exists():
        pytest.skip('no /proc/self/autogroup on this kernel: only the nice value can be checked')
    assert ag == '7'


def test_a_process_in_another_session_leaves_that_session_alone():
    if not AUTOGROUP.exists():
        pytest.skip('no /proc/self/autogroup on this kernel')
    before = _own_autogroup_nice()
    prio, ag = _run(7, own_session=False)
    assert prio == min(os.getpriority(os.PRIO_PROCESS, 0) + 7, 19)
    assert ag == before and _own_autogroup_nice() == before  # this test's session unchanged


def test_zero_changes_nothing():
    base = os.getpriority(os.PRIO_PROCESS, 0)
    prio, _ = _run(0, own_session=True)
    assert prio == base


def test_supervisor_nice_per_node(monkeypatch):
    """By default (``launch``) the view nodes yield, the loop's nodes do not; an int or a
    mapping overrides it."""
    got = {}

    class _P:
        pid = 0

    def fake_start_node(name, args, env=None, log=None, own_session=False, nice=0):
        got[name] = (own_session, nice)
        return _P()

    monkeypatch.setattr(processes, 'start_node', fake_start_node)
    SIDE_NICE = processes.SIDE_NICE
    sup = processes.Supervisor({})  # the default: what `launch` starts its nodes with
    for n in ('falcon_driver', 'force_server', 'visualizer', 'web_view'):
        sup.start(n)
    assert got == {'falcon_driver': (True, 0), 'force_server': (True, 0),
                   'visualizer': (True, SIDE_NICE), 'web_view': (True, SIDE_NICE)}
    sup_all = processes.Supervisor({}, nice=3)
    sup_all.start('force_server')
    assert got['force_server'] == (True, 3)
    processes.Supervisor({}, nice={'force_server': 5}).start('web_view')
    assert got['web_view'] == (True, 0)
