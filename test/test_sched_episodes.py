"""bench/sched_episodes.py's arithmetic: late local models found in the recorder's receive times,
and a scheduler trace's run / runnable / asleep stretches cut to each episode."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
from bench_sched_trace import TIMEHIST_LINE  # noqa: E402
from sched_episodes import (Episode, Use, account, by_process, find_episodes,  # noqa: E402
                            node_pids, parse_line, servo_gaps, summed)


def test_a_timehist_line_with_a_spaced_thread_name():
    m = TIMEHIST_LINE.match('   79809.726371 [0001]  dq.builtins x[2412/2400]      412.500'
                            '    300.250     50.000')
    assert m.groups() == ('79809.726371', '0001', 'dq.builtins x', '2412', '2400', '412.500',
                          '300.250', '50.000', None)


def test_the_longest_gaps_between_local_models_in_time_order():
    recv = np.array([0.0, 0.1, 0.7, 0.8, 1.1, 1.2, 2.2])   # gaps 0.6, 0.3, 1.0 > 0.25
    contact = np.array([0.05, 0.2, 0.3, 0.4, 1.5])
    eps = find_episodes(recv, contact, 0.25, 2, offset=100.0)
    assert [(e.start, e.end, e.contacts) for e in eps] == [
        (pytest.approx(-99.9), pytest.approx(-99.3), 3),
        (pytest.approx(-98.8), pytest.approx(-97.8), 1)]


def test_a_switch_out_is_cut_into_asleep_runnable_and_run_inside_the_episode():
    """A thread that slept 10.05-10.15 s, waited for a CPU 10.15-10.45 and ran 10.45-10.5:
    an episode 10.0-10.4 holds 100 ms asleep and 250 ms runnable of it, none run."""
    ep = Episode(10.0, 10.4, 0)
    names: dict[int, str] = {}
    lines = [(5.0, 0, 'force_server', 7, 7, 1.0, 0.0, 1.0, 'S'),   # before: names pid 7
             (10.5, 1, 'recvUC', 9, 7, 400.0, 300.0, 50.0, 'S'),
             (10.3, 0, '<idle>', 0, 0, 0.0, 0.0, 200.0, ''),         # idle 10.1-10.3
             (11.0, 0, 'busy', 3, 3, 0.0, 0.0, 400.0, 'R')]          # ran 10.6-11.0: after
    assert account([ep], iter(lines), names) == (5.0, 11.0, 2)
    u = ep.threads[7, 9]
    assert (u.run, u.runnable, u.asleep) == (pytest.approx(0.0), pytest.approx(250.0),
                                             pytest.approx(100.0))
    assert u.longest_wait == pytest.approx(300.0)
    assert ep.idle == pytest.approx(200.0)
    assert (3, 3) not in ep.threads
    assert names == {7: 'force_server', 3: 'busy'}
    proc = by_process(ep, names, {7})
    assert list(proc) == ['force_server[7]'] and proc['force_server[7]'].runnable == \
        pytest.approx(250.0)


def test_lines_of_perf_sched_timehist_state_the_idle_task_and_a_header():
    assert parse_line('   79809.726371 [0000]  migration/0[18]   0.000   0.009   0.013  S ') == (
        79809.726371, 0, 'migration/0', 18, 18, 0.0, 0.009, 0.013, 'S')
    assert parse_line('   79809.726639 [0001]  <idle>     0.000      0.000      0.200 ') == (
        79809.726639, 1, '<idle>', 0, 0, 0.0, 0.0, 0.2, '')
    assert parse_line('   79809.9 [0001]  python[25139/25099]  434.0  0.0  1.0  R') == (
        79809.9, 1, 'python', 25139, 25099, 434.0, 0.0, 1.0, 'R')
    assert parse_line('           time    cpu  task name     wait time  sch delay') is None


def test_a_preempted_threads_whole_wait_is_runnable():
    """Left its CPU preempted (R) at 10.0 s, ran again 10.4-10.45: perf 6.1 gives that wait no
    scheduler delay; it is runnable all the same, not asleep."""
    ep = Episode(10.0, 10.4, 0)
    lines = [(10.0, 0, 'force_server', 7, 7, 0.0, 0.0, 5.0, 'R'),
             (10.45, 0, 'force_server', 7, 7, 400.0, 0.0, 50.0, 'S')]
    account([ep], iter(lines), {})
    u = ep.threads[7, 7]
    assert (u.runnable, u.asleep, u.longest_wait) == (pytest.approx(400.0), 0.0,
                                                      pytest.approx(400.0))


def test_the_graphs_processes_from_the_node_logs(tmp_path):
    (tmp_path / 'force_server.log').write_text(
        '[INFO] [1795964801.5] [force_server]: no case\n'
        '[INFO] [1795964806.8] [force_server]: started after 5.7 s: constructed (kernels '
        'compiled, files loaded), process 25099\n')
    (tmp_path / 'falcon_driver.log').write_text(
        '[INFO] [1.0] [falcon_driver]: started after 2.9 s: constructed, process 25187\n'
        '[WARN] [2.0] [falcon_driver]: servo thread: compiled tick in servo process 25332 (own '
        'session); normal scheduler\n')
    assert node_pids(tmp_path) == {25099: 'force_server', 25187: 'falcon_driver',
                                   25332: 'servo process'}


def test_the_longest_servo_gaps_from_the_start_and_their_sum(capsys):
    t = np.arange(0.0, 2.0, 0.001)
    t = np.concatenate([t[t < 0.5], t[t >= 0.52]])         # 21 ms before --from: left out
    t = np.concatenate([t[t < 1.2], t[t >= 1.2] + 0.05])   # 51 ms at 1.2 s
    t = np.concatenate([t[t < 1.5], t[t >= 1.5] + 0.015])  # 16 ms at 1.5 s
    t = np.concatenate([t[t < 1.7], t[t >= 1.7] + 0.002])  # 3 ms: a period lost, not a gap
    rows = np.zeros((len(t), 8))
    rows[:, 0] = t
    eps = servo_gaps(rows, 1.0, 1)
    assert [(e.start, e.end) for e in eps] == [(pytest.approx(1.199), pytest.approx(1.25))]
    assert 'servo gaps from 1 s: 2 longer than 10 ms (0.07 s in all), 3 longer than 2 ms' in \
        capsys.readouterr().out
    a, b = Episode(0.0, 0.1, 0), Episode(1.0, 1.3, 0)
    a.threads[1, 1], b.threads[1, 1] = Use(1.0, 2.0, 3.0, 4.0), Use(10.0, 20.0, 30.0, 2.0)
    a.idle, b.idle = 5.0, 6.0
    s = summed([a, b])
    assert s.end - s.start == pytest.approx(0.4) and s.idle == 11.0
    assert s.threads[1, 1] == Use(11.0, 22.0, 33.0, 4.0)
