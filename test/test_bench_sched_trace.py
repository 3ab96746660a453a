"""The scheduler-trace benchmark's reading of ``perf sched timehist`` (synthetic lines: no perf,
no tracing right needed)."""
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_sched_trace import analyse, names_now, parse, program  # noqa: E402

SERVO, W1, BUSY, CHROME = 100, 102, 200, 300
W0 = SERVO  # the servo process's main thread is tick worker 0
HEAD = '''           time    cpu  task name                       wait time  sch delay   run time
                        [tid/pid]                          (msec)     (msec)     (msec)
--------------- ------  ------------------------------  ---------  ---------  ---------
'''


def line(t: float, cpu: int, comm: str, tid: int, pid: int, sch: float, run: float) -> str:
    task = f'{comm}[{tid}/{pid}]' if tid != pid else f'{comm}[{pid}]'
    return f'{t:15.6f} [{cpu:04d}]  {task:<30s}  {1.0:9.3f}  {sch:9.3f}  {run:9.3f}'


def test_delays_holders_and_a_gap_on_both_cores():
    rows = []
    t = 10.0
    for k in range(5):                       # 5 periods: each worker wakes on time
        rows += [line(t + 0.0002, 0, 'python', W0, SERVO, 0.01, 0.02),
                 line(t + 0.0003, 1, 'python', W1, SERVO, 0.02, 0.01)]
        t += 0.001
    # both cores held: the busy process 4 ms on core 0, chromium on core 1
    rows += [line(t + 0.004, 0, 'python', BUSY, BUSY, 0.0, 4.0),
             line(t + 0.0041, 0, 'python', W0, SERVO, 3.9, 0.02),
             line(t + 0.003, 1, 'Thread<00>', 301, CHROME, 0.0, 3.0),
             line(t + 0.0031, 1, 'python', W1, SERVO, 2.9, 0.02)]
    runs = parse(HEAD + '\n'.join(rows) + '\n')
    assert len(runs) == 14
    assert runs[-2][2:4] == (301, CHROME)
    s = analyse(sorted(runs), SERVO, {BUSY: 'busy process', CHROME: 'chromium'})
    assert s['wakeups'] == 10       # the first run on each core has no run before it
    assert s['max'] == pytest.approx(3.9)
    assert s['late_holders'] == {'busy process': 1, 'chromium': 1}
    assert s['held_for']['busy process'] == [4.0]
    assert s['gaps'] == 1
    assert s['gap_holders'] == {'busy process + chromium': 1}


def test_one_worker_late_is_no_gap_while_the_other_ticks():
    """Worker 1 held off its core for 4 ms by chromium while worker 0 (the servo process's main
    thread) runs every period on the other: a late wake-up, no servo gap."""
    rows = []
    t = 10.0
    for k in range(8):
        rows.append(line(t + 0.0002, 0, 'servo-tick0', W0, SERVO, 0.01, 0.02))
        t += 0.001
    rows += [line(10.0003, 1, 'servo-tick1', W1, SERVO, 0.02, 0.01),
             line(10.0043, 1, 'Thread<00>', 301, CHROME, 0.0, 4.0),
             line(10.0044, 1, 'servo-tick1', W1, SERVO, 3.9, 0.02)]
    s = analyse(sorted(parse(HEAD + '\n'.join(rows) + '\n')), SERVO, {CHROME: 'chromium'})
    assert s['gaps'] == 0
    assert s['late_holders'] == {'chromium': 1}
    assert s['wakeups'] == 7 + 1   # each core's runs after its first


def test_programs_named_from_command_lines():
    assert program('python -c while True: pass', 1, 2) == 'busy process'
    assert program('/usr/lib/chromium/chromium --type=gpu-process', 1, 2) == 'chromium'
    assert program('.venv/bin/python .venv/bin/web_view --ros-args', 1, 2) == 'web_view'
    assert program('python -m haptic_anfis.cli sim --duration 30', 1, 2) == 'sim graph'
    assert program('python -m haptic_anfis.cli sim --duration 30', 2, 2) == 'servo process'
    assert program('', 1, 2) == 'kernel'


def test_without_perf_it_says_so_and_ends_without_a_page(monkeypatch, capsys, tmp_path):
    import bench_sched_trace
    monkeypatch.setattr(bench_sched_trace.shutil, 'which', lambda name: None)
    monkeypatch.setattr(sys, 'argv', ['bench_sched_trace.py', '--page', 'x'])
    written = []
    monkeypatch.setattr(bench_sched_trace, 'write_page', lambda *a, **k: written.append(a))
    assert bench_sched_trace.main() == 0   # make bench goes on
    assert 'skipped: perf is not installed' in capsys.readouterr().out
    assert written == []


def test_threads_are_named_after_their_process():
    """A thread the trace names by its own id is its process's program (it was 'exited')."""
    import os
    import threading
    seen, stop = [], threading.Event()
    th = threading.Thread(target=lambda: (seen.append(threading.get_native_id()), stop.wait()))
    th.start()
    try:
        while not seen:
            pass
        names = names_now(servo_pid=os.getpid())
        assert names[seen[0]] == names[os.getpid()] == 'servo process'
    finally:
        stop.set()
        th.join()
