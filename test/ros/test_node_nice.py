"""Nodes off the haptic loop start at a lower CPU priority in every layout (issue 32)."""
from __future__ import annotations

from haptic_anfis.realtime import processes


def test_supervisor_starts_the_view_nodes_niced_and_the_loop_nodes_not(monkeypatch):
    """By default (what ``launch`` starts its nodes with) the view nodes yield and the loop's
    nodes do not; an int or a mapping overrides it."""
    got = {}

    class _P:
        pid = 0

    def fake_start_node(name, args, env=None, log=None, own_session=False, nice=0,
                        stop_with_parent=None):
        assert stop_with_parent  # no terminal signal reaches a launched node: SIGINT on death
        got[name] = (own_session, nice)
        return _P()

    monkeypatch.setattr(processes, 'start_node', fake_start_node)
    side = processes.SIDE_NICE
    assert side > 0
    sup = processes.Supervisor({})
    for n in ('falcon_driver', 'contact_detector', 'force_server', 'recorder', 'visualizer',
              'web_view'):
        sup.start(n)
    assert got == {'falcon_driver': (True, 0), 'contact_detector': (True, 0),
                   'force_server': (True, 0), 'recorder': (True, 0),
                   'visualizer': (True, side), 'web_view': (True, side)}
    processes.Supervisor({}, nice=3).start('force_server')
    assert got['force_server'] == (True, 3)
    processes.Supervisor({}, nice={'force_server': 5}).start('web_view')
    assert got['web_view'] == (True, 0)



def test_supervisor_starts_the_nodes_in_its_own_session_when_told(monkeypatch):
    """``launch --node-sessions one``: the nodes in the launcher's session (the view nodes'
    nice then counts against the loop's nodes), still stopped when the launcher dies."""
    got = {}

    class _P:
        pid = 0

    def fake_start_node(name, args, env=None, log=None, own_session=False, nice=0,
                        stop_with_parent=None):
        got[name] = (own_session, nice, stop_with_parent)
        return _P()

    monkeypatch.setattr(processes, 'start_node', fake_start_node)
    sup = processes.Supervisor({})
    sup.own_sessions = False
    sup.start('force_server')
    sup.start('web_view')
    assert got == {'force_server': (False, 0, True),
                   'web_view': (False, processes.SIDE_NICE, True)}
