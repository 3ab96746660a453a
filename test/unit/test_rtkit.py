"""Real-time priority from RealtimeKit (haptic_anfis.realtime.rtkit) against a fake system bus, and
the servo threads' choice of scheduling (realtime/scheduling.py): FIFO, else rtkit, else a short slice."""
from __future__ import annotations

import os
import resource
import threading

import jeepney
import pytest

from haptic_anfis.realtime import rtkit, scheduling
from haptic_anfis.realtime.rtkit import RealtimeKitError, make_thread_realtime


class FakeBus:
    """A blocking jeepney connection that answers as rtkit-daemon would (or with ``error``)."""

    def __init__(self, max_priority=20, usec=200_000, error=None,
                 fail_on='MakeThreadRealtimeWithPID'):
        self.max_priority, self.usec, self.error, self.fail_on = max_priority, usec, error, fail_on
        self.calls, self.closed = [], False

    def close(self):
        self.closed = True

    def send_and_get_reply(self, msg, timeout=None):
        f = msg.header.fields
        member = f[jeepney.HeaderFields.member]
        self.calls.append((f[jeepney.HeaderFields.destination], member, msg.body, timeout))
        if self.error and (member == self.fail_on or self.fail_on is None):
            return jeepney.new_error(msg, self.error, 's', ('not allowed',))
        if member == 'Get':
            value = {'MaxRealtimePriority': ('i', self.max_priority),
                     'RTTimeUSecMax': ('x', self.usec)}[msg.body[1]]
            return jeepney.new_method_return(msg, 'v', (value,))
        return jeepney.new_method_return(msg)


@pytest.fixture
def limits(monkeypatch):
    """RLIMIT_RTTIME as this process would set it (recorded, not applied)."""
    got = []
    monkeypatch.setattr(rtkit, 'limit_rttime',
                        lambda usec, pid=0, soft_usec=None: got.append(
                            usec if (pid, soft_usec) == (0, None) else (usec, pid, soft_usec)))
    return got


def test_asks_rtkit_for_this_thread_at_most_its_priority(limits):
    bus = FakeBus(max_priority=20, usec=150_000)
    assert make_thread_realtime(50, connect=lambda: bus, timeout=1.5) == 20
    assert limits == [150_000] and bus.closed
    dest, member, body, timeout = bus.calls[-1]
    assert (dest, member, timeout) == (rtkit.SERVICE, 'MakeThreadRealtimeWithPID', 1.5)
    assert body == (os.getpid(), threading.get_native_id(), 20)
    assert make_thread_realtime(5, tid=1234, connect=lambda: FakeBus()) == 5  # below the max


@pytest.mark.parametrize('error, words', [
    ('org.freedesktop.DBus.Error.ServiceUnknown', 'no rtkit-daemon on this machine'),
    ('org.freedesktop.DBus.Error.AccessDenied', 'rtkit refused (polkit'),
    ('org.example.Odd', 'org.example.Odd: not allowed'),
])
def test_an_error_reply_is_one_line_naming_it(limits, error, words):
    with pytest.raises(RealtimeKitError, match=r'^rtkit: ') as e:
        make_thread_realtime(50, connect=lambda: FakeBus(error=error))
    assert words in str(e.value) and '\n' not in str(e.value)


def test_max_priority_says_whether_rtkit_answers():
    assert rtkit.max_realtime_priority(connect=lambda: FakeBus(max_priority=15)) == 15
    with pytest.raises(RealtimeKitError, match='no rtkit-daemon'):
        rtkit.max_realtime_priority(connect=lambda: FakeBus(
            error='org.freedesktop.DBus.Error.ServiceUnknown', fail_on=None))


def test_no_service_fails_before_any_limit_is_changed(limits):
    with pytest.raises(RealtimeKitError, match='no rtkit-daemon'):
        make_thread_realtime(50, connect=lambda: FakeBus(
            error='org.freedesktop.DBus.Error.ServiceUnknown', fail_on=None))
    assert limits == []


def test_no_bus_and_a_bad_priority_are_said(limits):
    def no_socket():
        raise FileNotFoundError(2, 'No such file or directory')
    with pytest.raises(RealtimeKitError, match=r'rtkit: no system D-Bus \(.*No such file'):
        make_thread_realtime(50, connect=no_socket)
    with pytest.raises(ValueError, match='priority'):
        make_thread_realtime(0)


@pytest.mark.parametrize('before, usec, after', [
    ((resource.RLIM_INFINITY, resource.RLIM_INFINITY), 200_000, (200_000, 200_000)),
    ((50_000, resource.RLIM_INFINITY), 200_000, (50_000, 200_000)),
    ((50_000, 100_000), 200_000, (50_000, 100_000)),        # lower already: kept
    ((resource.RLIM_INFINITY, 300_000), 200_000, (200_000, 200_000)),
])
def test_the_run_time_limit_is_only_ever_lowered(monkeypatch, before, usec, after):
    got = []
    monkeypatch.setattr(resource, 'getrlimit', lambda which: before)
    monkeypatch.setattr(resource, 'setrlimit', lambda which, lim: got.append((which, lim)))
    rtkit.limit_rttime(usec)
    assert got == [(resource.RLIMIT_RTTIME, after)]


def test_servo_thread_falls_back_to_rtkit_then_to_a_short_slice(monkeypatch):
    """FIFO refused: rtkit's SCHED_RR when it grants it (no short slice then); refused by both:
    the fair scheduler with the short slice, and a line saying both reasons."""
    def refuse(*a):
        raise PermissionError(1, 'Operation not permitted')
    monkeypatch.setattr(os, 'sched_setscheduler', refuse)
    sliced = []
    monkeypatch.setattr(scheduling, 'request_short_slice', lambda: sliced.append(1) or ', slice')
    monkeypatch.setattr(rtkit, 'make_thread_realtime', lambda priority: min(priority, 20))
    monkeypatch.setattr(scheduling, 'is_realtime', lambda: True)
    said = scheduling.schedule_servo_thread(50)
    assert said == 'SCHED_RR priority 20 from rtkit, in place of SCHED_FIFO 50' and not sliced
    assert 'refused' in scheduling.set_realtime(50)  # rtkit only when asked for

    def kit_refuses(priority):
        raise RealtimeKitError('rtkit: no rtkit-daemon on this machine')
    monkeypatch.setattr(rtkit, 'make_thread_realtime', kit_refuses)
    monkeypatch.setattr(scheduling, 'is_realtime', lambda: False)
    said = scheduling.schedule_servo_thread(50)
    assert said.startswith('normal scheduler: SCHED_FIFO 50 refused (Operation not permitted; '
                           'rtkit: no rtkit-daemon on this machine)') and said.endswith(', slice')
    assert sliced == [1]
    assert scheduling.schedule_servo_thread(0) == 'normal scheduler (priority 0), slice'


def test_threads_of_another_process_over_one_connection_each_refusal_said(limits):
    """The graph's nodes are raised by their launcher: threads of another process, the soft
    limit below rtkit's; a refused thread (one that ended, rtkit's per-user limits) is named,
    the others are raised."""
    class Refuses(FakeBus):
        def send_and_get_reply(self, msg, timeout=None):
            if msg.body and msg.body[:2] == (4321, 12):
                self.calls.append(('refused', msg.body))
                return jeepney.new_error(msg, 'org.freedesktop.DBus.Error.Failed', 's',
                                         ('Reached burst limit',))
            return super().send_and_get_reply(msg, timeout)
    bus = Refuses(max_priority=20, usec=200_000)
    granted, refused = rtkit.make_threads_realtime(10, [11, 12, 13], 4321, soft_share=0.5,
                                                   connect=lambda: bus)
    assert granted == 10 and list(refused) == [12] and bus.closed
    assert refused[12] == 'rtkit: org.freedesktop.DBus.Error.Failed: Reached burst limit'
    assert limits == [(200_000, 4321, 100_000)]
    asked = [c[2] for c in bus.calls if c[1] == 'MakeThreadRealtimeWithPID']
    assert asked == [(4321, 11, 10), (4321, 13, 10)]


def test_the_soft_limit_of_another_process_is_lowered_with_prlimit(monkeypatch):
    got = []
    monkeypatch.setattr(resource, 'prlimit', lambda pid, which, lim=None: got.append(
        (pid, lim)) or (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    rtkit.limit_rttime(200_000, pid=99, soft_usec=100_000)
    assert got == [(99, None), (99, (100_000, 200_000))]


def test_is_realtime_reads_the_policy_without_the_reset_on_fork_flag(monkeypatch):
    monkeypatch.setattr(os, 'sched_getscheduler', lambda pid: os.SCHED_RR | scheduling.RESET_ON_FORK)
    assert scheduling.is_realtime()
    monkeypatch.setattr(os, 'sched_getscheduler', lambda pid: os.SCHED_OTHER)
    assert not scheduling.is_realtime()


def test_off_realtime_steps_off_and_back_through_rtkit_when_fifo_is_refused(monkeypatch):
    """A real-time thread runs the block under the normal scheduler (the reset-on-fork flag
    rtkit set is kept: only a privileged thread may clear it), then gets its priority back:
    SCHED_FIFO where allowed, else from rtkit; a thread that is not real-time is left alone.
    Fakes only: this test process's own policy never changes."""
    state = {'policy': os.SCHED_RR | scheduling.RESET_ON_FORK, 'prio': 10}
    calls, kit = [], []

    def setscheduler(tid, policy, param):
        calls.append((policy, param.sched_priority))
        if policy & ~scheduling.RESET_ON_FORK != os.SCHED_OTHER:
            raise PermissionError(1, 'Operation not permitted')
        state.update(policy=policy, prio=0)
    monkeypatch.setattr(os, 'sched_getscheduler', lambda tid: state['policy'])
    monkeypatch.setattr(os, 'sched_getparam', lambda tid: os.sched_param(state['prio']))
    monkeypatch.setattr(os, 'sched_setscheduler', setscheduler)
    monkeypatch.setattr(rtkit, 'make_thread_realtime', lambda priority: kit.append(priority))
    with scheduling.off_realtime():
        assert not scheduling.is_realtime()
    assert calls == [(os.SCHED_OTHER | scheduling.RESET_ON_FORK, 0),
                     (os.SCHED_RR | scheduling.RESET_ON_FORK, 10)]
    assert kit == [10]
    calls.clear()
    with scheduling.off_realtime():  # normal already: nothing to do
        pass
    assert calls == [] and kit == [10]


def test_off_realtime_gives_a_privileged_thread_its_own_policy_back(monkeypatch):
    """A thread allowed to set its policy comes back with the one it had (SCHED_RR stays RR,
    not the SCHED_FIFO a fresh request asks for), and rtkit is not asked. Fakes only."""
    state = {'policy': os.SCHED_RR, 'prio': 30}

    def setscheduler(tid, policy, param):
        state.update(policy=policy, prio=param.sched_priority)
    monkeypatch.setattr(os, 'sched_getscheduler', lambda tid: state['policy'])
    monkeypatch.setattr(os, 'sched_getparam', lambda tid: os.sched_param(state['prio']))
    monkeypatch.setattr(os, 'sched_setscheduler', setscheduler)
    monkeypatch.setattr(rtkit, 'make_thread_realtime', lambda priority: pytest.fail('rtkit'))
    with scheduling.off_realtime():
        assert state == {'policy': os.SCHED_OTHER, 'prio': 0}
    assert state == {'policy': os.SCHED_RR, 'prio': 30}
    assert scheduling.set_realtime(30, policy=os.SCHED_RR) == 'SCHED_RR priority 30'
