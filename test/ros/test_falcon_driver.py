"""falcon_driver (ROS node, in process): parameters, the missing USB library, the servo loop's
start and its health warnings. Runs against the fake FTDI device are in
test_falcon_servo_process.py. No hardware."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.parameter import Parameter  # noqa: E402

from haptic_anfis.device import falcon_usb  # noqa: E402
from haptic_anfis.nodes.parameters import ParameterError  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def driver(ctx, **params):
    from haptic_anfis.nodes.falcon_driver import FalconDriver
    d = FalconDriver(context=ctx, parameter_overrides=[
        Parameter(n, value=v) for n, v in params.items()])
    try:
        d.start_loop()
    except BaseException:  # a node left undestroyed stays on the graph until collected
        d.close()
        d.destroy_node()
        raise
    return d


def test_unknown_backend_is_rejected_naming_the_choices(ctx):
    with pytest.raises(ParameterError, match=r"backend.*'sim', 'falcon'"):
        driver(ctx, backend='usb')


def test_falcon_parameters_are_checked(ctx):
    with pytest.raises(ParameterError, match='firmware_attempts'):
        driver(ctx, backend='falcon', firmware_attempts=0)


def test_falcon_backend_without_usb_library_says_how_to_install(ctx, monkeypatch):
    monkeypatch.setitem(sys.modules, 'pyftdi', None)
    monkeypatch.setitem(sys.modules, 'pyftdi.ftdi', None)
    with pytest.raises(falcon_usb.FalconUnavailableError, match=r"haptic_anfis\[falcon\]"):
        driver(ctx, backend='falcon')


def test_node_process_exits_1_with_one_line_error_without_the_usb_library(tmp_path):
    """The console script's path: run_node prints the FalconError and exits 1 (no traceback)."""
    code = ("import sys; sys.modules['pyftdi'] = None; sys.modules['pyftdi.ftdi'] = None\n"
            "from haptic_anfis.nodes.falcon_driver import main\n"
            "main(['falcon_driver', '--ros-args', '-p', 'backend:=falcon'])\n")
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=60,
                       cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    assert "error: backend 'falcon' needs the optional USB library pyftdi" in r.stderr
    assert "pip install 'haptic_anfis[falcon]'" in r.stderr and 'Traceback' not in r.stderr


def test_the_servo_starts_once_the_node_is_told_not_when_it_is_built(ctx):
    """Built, the driver's servo does not run yet (its bridge thread would share the interpreter
    lock with the rest of the process's start); start_loop starts it, once."""
    from haptic_anfis.nodes.falcon_driver import FalconDriver
    d = FalconDriver(context=ctx)
    try:
        assert not d.started and not d.servo.running
    finally:
        d.close()  # never started: nothing to stop, no error
        d.destroy_node()
    d = FalconDriver(context=ctx)
    try:
        d.start_loop()
        assert d.started and d.servo.running
        bridge = d.servo._bridge
        d.start_loop()  # idempotent: the same loop
        assert d.servo._bridge is bridge
    finally:
        d.close()
        d.destroy_node()
    assert not d.servo.running


def test_run_node_starts_a_nodes_loop_after_the_process_settled(tmp_path):
    """run_node calls start_loop once the node is built, its executor made and the garbage
    collector settled (frozen), before the first spin."""
    code = ("import gc, sys\n"
            "from rclpy.node import Node\n"
            "from haptic_anfis.nodes.runtime import run_node\n"
            "class N(Node):\n"
            "    def __init__(self):\n"
            "        super().__init__('loop_probe')\n"
            "        self.spun = False\n"
            "        self.create_timer(0.01, self._tick)\n"
            "    def _tick(self):\n"
            "        self.spun = True\n"
            "        self.finished = True\n"
            "    def start_loop(self):\n"
            "        print('frozen', gc.get_freeze_count() > 0, 'spun', self.spun, flush=True)\n"
            "sys.exit(run_node(N, ['loop_probe']))\n")
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=60,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines().count('frozen True spun False') == 1, r.stdout


def test_a_negative_loop_check_period_is_refused(ctx):
    with pytest.raises(ParameterError, match='loop_check_period'):
        driver(ctx, loop_check_period=-1.0)


def test_the_driver_warns_when_its_loop_falls_behind(ctx, monkeypatch):
    """Every loop_check_period the driver checks its loop's counters (device/loop_health.py) and
    warns, with what to do, when the window lost more than 0.5 % of its periods (at most once a
    minute); the windows checked and those behind are in its summary (sim --json, the trace)."""
    from types import SimpleNamespace

    from haptic_anfis.device.loop_health import LoopHealth
    d = driver(ctx, loop_check_period=10.0)
    try:
        d.health = LoopHealth(d.params['watchdog_timeout'])   # no reading from start_loop
        readings = [{'ticks': 1000, 'periods_lost': 0, 'gaps_past_watchdog': 0, 'seconds': 1.0},
                    {'ticks': 10940, 'periods_lost': 60, 'gaps_past_watchdog': 0,
                     'seconds': 11.0}]
        summary = d.servo.stats.summary
        monkeypatch.setattr(d.servo.stats, 'summary',
                            lambda: readings.pop(0) if readings else summary())
        said = []
        monkeypatch.setattr(d, 'get_logger', lambda: SimpleNamespace(
            warning=lambda msg, **kw: said.append((msg, kw))))
        d.pub_diag = SimpleNamespace(published=[])
        d.pub_diag.publish = d.pub_diag.published.append
        d._check_loop()   # the first reading starts the window
        assert said == []
        d._check_loop()
        assert len(said) == 1
        msg, kw = said[0]
        assert msg.startswith('servo loop fell behind over the last 10.0 s: 0.60 % of its '
                              'periods lost (60 of 10000')
        assert d.behind_because() in msg and msg.endswith('(1 of 1 windows so far)')
        assert kw == {'throttle_duration_sec': 60.0}
        s = d.summary()
        assert (s['loop_windows'], s['loop_windows_behind']) == (1, 1)
        # and on ROS's diagnostics topic, for the page and rqt_robot_monitor: each window checked
        diag = d.pub_diag.published
        from diagnostic_msgs.msg import DiagnosticStatus
        assert len(diag) == 1 and diag[0].status[0].level == DiagnosticStatus.WARN
        st = diag[0].status[0]
        assert st.name == 'falcon_driver: servo loop' and st.message.startswith('servo loop fell')
        v = {kv.key: kv.value for kv in st.values}
        assert (v['windows'], v['windows_behind'], v['cause']) == ('1', '1', d.behind_because())
    finally:
        d.close()
        d.destroy_node()


@pytest.mark.parametrize('period, timers', [(10.0, 1), (0.0, 0)])
def test_loop_check_period_sets_the_checks_timer(ctx, monkeypatch, period, timers):
    from rclpy.node import Node

    from haptic_anfis.nodes.falcon_driver import FalconDriver
    made = []
    create = Node.create_timer
    monkeypatch.setattr(FalconDriver, 'create_timer',
                        lambda self, *a, **kw: made.append(a[0]) or create(self, *a, **kw))
    d = FalconDriver(context=ctx, parameter_overrides=[
        Parameter('loop_check_period', value=period)])
    try:
        assert made.count(period) == timers
    finally:
        d.close()
        d.destroy_node()


@pytest.mark.parametrize('backend', ['sim', 'falcon'])
def test_the_python_tick_is_no_servo_loop_choice(ctx, backend):
    """Every backend runs the compiled tick: 'python' is refused in one line naming the
    choices."""
    with pytest.raises(ParameterError, match=r"servo_loop.*'auto', 'native', 'native_process'"):
        driver(ctx, backend=backend, servo_loop='python')


def test_a_loop_check_period_under_a_second_is_refused(ctx):
    with pytest.raises(ParameterError, match='loop_check_period'):
        driver(ctx, loop_check_period=0.5)


@pytest.mark.parametrize('loop, backend, realtime, scheduling, cause', [
    ('native_process', 'sim', False, 'compiled tick in servo process 7 (own session); normal '
     'scheduler: SCHED_FIFO 50 refused (no right); short time slice',
     'runs under the normal scheduler'),
    ('native_process', 'sim', False, 'compiled tick in servo process 7 (own session); normal '
     'scheduler (priority 0)', 'runs under the normal scheduler'),
    ('native_process', 'sim', True, 'compiled tick in servo process 7 (own session); SCHED_FIFO '
     'priority 50', 'the machine itself stalled (docs'),
    ('native_process', 'falcon', True, 'SCHED_RR priority 20 from rtkit, in place of SCHED_FIFO '
     '50', "the machine itself stalled, or the device's USB replies came late"),
    # demoted since the start (rtkit's run-time limit): the threads' policy now, not the line
    ('native_process', 'sim', False, 'SCHED_RR priority 20 from rtkit, in place of SCHED_FIFO '
     '50', 'runs under the normal scheduler'),
    ('native_process', 'sim', None, '', "the servo thread's scheduling: not reported")])
def test_the_warning_names_the_likely_cause(ctx, monkeypatch, loop, backend, realtime,
                                            scheduling, cause):
    """The cause follows the servo threads' policy as the kernel reports it
    (``processes.servo_realtime``; None: no servo thread found)."""
    from haptic_anfis.realtime import processes
    d = driver(ctx)
    try:
        monkeypatch.setattr(processes, 'servo_realtime',
                            lambda pid: realtime if pid == os.getpid() else None)
        d.servo_loop, d.params = loop, {**d.params, 'backend': backend}
        d.servo.scheduling = scheduling
        assert cause in d.behind_because()
    finally:
        d.close()
        d.destroy_node()


def test_a_force_scale_set_while_running_is_rendered_and_published_with(ctx):
    """A case switched live (the browser page) sets the case's own force scale on the driver:
    the loop, its force input and the applied force it publishes (tissue frame) take it; a
    scale that is no scale is refused and the others stay read-only."""
    from haptic_anfis.device import native_tick as nt
    d = driver(ctx, force_scale=0.5)
    try:
        assert d.servo.cfg[nt.CFG.force_scale] == 0.5
        assert d.set_parameters([Parameter('force_scale', value=0.25)])[0].successful
        assert d.mapping.force_scale == d.input.mapping.force_scale == 0.25
        assert d.servo.mapping.force_scale == d.servo.cfg[nt.CFG.force_scale] == 0.25
        assert d.get_parameter('force_scale').value == 0.25
        bad = d.set_parameters([Parameter('force_scale', value=-1.0)])[0]
        assert not bad.successful and 'force_scale' in bad.reason
        assert not d.set_parameters([Parameter('max_force', value=1.0)])[0].successful
        assert d.mapping.force_scale == 0.25 and d.params['max_force'] == 8.9
    finally:
        d.close()
        d.destroy_node()
