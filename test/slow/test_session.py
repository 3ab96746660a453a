"""Issue 20: readiness, respawn, clean interrupted start (cross-process), the start gate.

Cross-process tests use their own ROS_DOMAIN_ID and localhost discovery; waits are generous
(discovery and a warm node start take seconds on a loaded machine); nothing asserts timings.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from haptic_anfis.device import PalpationScript
from haptic_anfis.device.start_gate import HeldScript
from haptic_anfis.realtime.processes import Supervisor, renamed_output

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / 'config' / 'palpation.yaml'


def test_held_script_waits_at_the_start_then_runs_from_its_own_zero():
    s = PalpationScript.from_yaml(SCRIPT)
    h = HeldScript(s)
    start = s.target(0.0)
    for t in (0.0, 3.0, 50.0):  # held: the first point, whatever the device time
        assert h.target(t) == start and h.is_pressing(t) == s.is_pressing(0.0)
    assert h.held
    h.release()
    assert h.target(50.0) == start  # the script's clock starts at the first query after release
    for dt in (0.5, 2.0, 7.25):
        assert h.target(50.0 + dt) == s.target(dt)
        assert h.is_pressing(50.0 + dt) == s.is_pressing(dt)
    assert not h.held and h.duration == s.duration
    free = HeldScript(s, held=False)
    assert free.target(2.0) == s.target(2.0)


def test_held_script_passes_the_scripts_buttons_through(tmp_path):
    # the simulated Falcon reads the hand's grip buttons from the (held) script every tick
    p = tmp_path / 'mark.yaml'
    p.write_text('surface:\n  radii: [0.045, 0.070, 0.070]\nloop: false\npattern:\n'
                 '  - mark: {points: [[0.0, 0.0]], depth: 0.008, hold: 1.0}\n')
    s = PalpationScript.from_yaml(p)
    ts = [0.01 * i for i in range(int(s.duration * 100))]
    pressed = [t for t in ts if s.buttons(t)[1]]
    assert pressed, 'the mark move presses button 1'
    h = HeldScript(s)
    assert h.buttons(pressed[0]) == (0, 0)  # held: the hand waits, nothing pressed
    h.release()
    h.target(10.0)  # the script's clock starts here
    assert h.buttons(10.0 + pressed[0]) == s.buttons(pressed[0]) == (0, 1)


def test_recorder_restart_writes_a_new_bag_directory():
    assert renamed_output(['-p', 'output:=/x/bag', '-p', 'a:=1'], 2) == \
        ['-p', 'output:=/x/bag.restart2', '-p', 'a:=1']
    with pytest.raises(ValueError, match='max_restarts'):
        Supervisor({}, max_restarts=-1)


rclpy = pytest.importorskip('rclpy')
_domain = 60 + os.getpid() % 30 * 2


def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if k != '_ROS_WHEELS_BOOTSTRAP_COMPLETE'}
    env['PYTHONPATH'] = str(ROOT)
    return env


def _wait_line(out: Path, pattern: str, timeout: float) -> re.Match:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = re.search(pattern, out.read_text())
        if m:
            return m
        time.sleep(0.5)
    raise AssertionError(f'no {pattern!r} within {timeout} s:\n{out.read_text()[-3000:]}')


@pytest.mark.ros
def test_in_process_graph_reports_ready_on_the_latched_status_topic(monkeypatch):
    """Every node of the one-process graph says started, then ready; the driver's readiness is
    the first force command, and its hand held still (no pressing) until then."""
    from haptic_anfis.nodes.graph import build_graph
    monkeypatch.setenv('ROS_DOMAIN_ID', str(_domain))
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    g = build_graph(None, visualizer=False)
    try:
        assert g.driver.device.script.held or g.driver.first_command is not None
        waited = g.wait_ready(120.0)
        assert waited is not None
        g.spin_for(1.0)
        states = {n.get_name(): n.readiness.state for n in g.nodes}
        assert states == {'falcon_driver': 'ready', 'contact_detector': 'ready',
                          'force_server': 'ready'}, states
        assert not g.driver.device.script.held
    finally:
        g.shutdown()


@pytest.mark.ros
def test_launch_respawns_killed_nodes_and_the_bag_is_complete(tmp_path):
    """kill -9 of force_server, then of contact_detector, in a recording launch: both restart,
    the session goes on (poses never stop), force returns, the events are in a complete bag."""
    from haptic_anfis.bag import read_messages
    bag, out = tmp_path / 'bag', tmp_path / 'launch.out'
    p = subprocess.Popen([sys.executable, '-m', 'haptic_anfis.cli', 'launch', '--nodes',
                          'falcon_driver,contact_detector,force_server', '--duration', '60',
                          '--domain-id', str(_domain + 1), '--localhost', '--record', str(bag),
                          '--log-dir', str(tmp_path / 'logs')], cwd=ROOT, env=_env(),
                         stdout=out.open('w'), stderr=subprocess.STDOUT)
    try:
        _wait_line(out, r'ready after', 300)
        kills = {}
        for node in ('force_server', 'contact_detector'):
            pid = int(_wait_line(out, rf'started {node} +pid (\d+)', 10).group(1)) if not kills \
                else int(re.findall(rf'(?:started {node} +pid|node {node}, pid) (\d+)',
                                    out.read_text())[-1])
            time.sleep(3.0)
            kills[node] = time.time()
            os.kill(pid, signal.SIGKILL)
            _wait_line(out, rf'restarted, .*node {node}', 60)
            # allow the restart + discovery (>= 10 s) before the next kill
            time.sleep(12.0)
        assert p.wait(300) == 0, out.read_text()
    finally:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            p.wait(60)
    text = out.read_text()
    events = [json.loads(m.data) for *_, m in read_messages(bag, ['/session/events'])]
    kinds = [(e['event'], e.get('node')) for e in events]
    for node in kills:
        assert ('died', node) in kinds and ('restarted', node) in kinds, kinds
    assert ('died', 'falcon_driver') not in kinds
    # the driver kept publishing through each outage (pose stamps = its clock)
    poses = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
                      for *_, m in read_messages(bag, ['/falcon/measured_cp'])])
    cmds = [(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
             abs(m.wrench.force.x) + abs(m.wrench.force.y) + abs(m.wrench.force.z))
            for *_, m in read_messages(bag, ['/falcon/servo_cf'])]
    for node, t_kill in kills.items():
        assert np.sum((poses > t_kill) & (poses < t_kill + 3.0)) > 100, node
        back = [t for t, f in cmds if t > t_kill + 0.5 and f > 0.0]
        assert back, f'no force after killing {node}'
        print(f'{node}: force back {back[0] - t_kill:.1f} s after kill -9')
    assert (bag / 'metadata.yaml').is_file()  # closed properly: summary and metadata written


@pytest.mark.ros
def test_no_respawn_stops_the_launch_when_a_node_dies(tmp_path):
    out = tmp_path / 'launch.out'
    p = subprocess.Popen([sys.executable, '-m', 'haptic_anfis.cli', 'launch', '--nodes',
                          'falcon_driver,contact_detector,force_server', '--duration', '120',
                          '--domain-id', str(_domain + 2), '--localhost', '--no-respawn',
                          '--log-dir', str(tmp_path / 'logs')], cwd=ROOT, env=_env(),
                         stdout=out.open('w'), stderr=subprocess.STDOUT)
    try:
        _wait_line(out, r'ready after', 300)
        pid = int(_wait_line(out, r'started contact_detector +pid (\d+)', 5).group(1))
        os.kill(pid, signal.SIGKILL)
        assert p.wait(120) == 1
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(30)
    text = out.read_text()
    assert 'reason --no-respawn' in text and 'restarted' not in text, text


@pytest.mark.ros
def test_node_interrupted_while_starting_exits_cleanly(tmp_path):
    """SIGINT as soon as the node exists in the graph (it is still loading its mesh and
    compiling): exit code 0 and no traceback, whichever moment the signal lands."""
    from rclpy.context import Context

    from haptic_anfis.realtime.processes import node_env, start_node
    domain = _domain + 3
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    obs = rclpy.create_node('observer', context=ctx)
    log = tmp_path / 'cd.log'
    p = start_node('contact_detector', env={**node_env(domain, localhost=True),
                                           'PYTHONPATH': str(ROOT)}, log=log.open('w'))
    try:
        end = time.monotonic() + 120
        while 'contact_detector' not in obs.get_node_names() and time.monotonic() < end:
            time.sleep(0.02)
        p.send_signal(signal.SIGINT)
        assert p.wait(60) == 0, log.read_text()
    finally:
        if p.poll() is None:
            p.kill()
        obs.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert 'Traceback' not in log.read_text(), log.read_text()


@pytest.mark.ros
@pytest.mark.parametrize('module, cls, param, value', [
    ('trainer', 'Trainer', 'model_path', '/tmp/evil_model.json'),
    ('force_server', 'ForceServer', 'model_path', '/tmp/evil_model.json'),
    ('contact_detector', 'ContactDetectorNode', 'mesh_path', '/tmp/evil.stl'),
    ('recorder', 'Recorder', 'output', '/tmp/evil_bag'),
])
def test_path_parameters_are_read_only_after_start(tmp_path, module, cls, param, value):
    """A peer's ``set_parameters`` (what the parameter service runs) cannot move a node's files."""
    import importlib

    from rclpy.context import Context
    from rclpy.parameter import Parameter
    ctx = Context()
    rclpy.init(context=ctx, domain_id=_domain + 4)
    kw = {'output': str(tmp_path / 'bag')} if cls == 'Recorder' else {}
    node = getattr(importlib.import_module(f'haptic_anfis.nodes.{module}'), cls)(context=ctx, **kw)
    try:
        before = node.get_parameter(param).value
        result = node.set_parameters([Parameter(param, value=value)])[0]
        assert not result.successful and 'read-only' in result.reason
        assert node.get_parameter(param).value == before
    finally:
        if hasattr(node, 'close'):
            node.close()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.mark.ros
def test_killed_recorder_restarts_into_a_new_bag_with_the_events(tmp_path):
    """kill -9 of the recorder: it restarts into BAG.restart1, which gets the session's events
    replayed; the killed bag is recoverable. Nodes run with --enclave (security off: accepted)."""
    from haptic_anfis.bag import read_messages
    from haptic_anfis.cli import main as cli
    bag, out = tmp_path / 'bag', tmp_path / 'launch.out'
    p = subprocess.Popen([sys.executable, '-m', 'haptic_anfis.cli', 'launch', '--nodes',
                          'falcon_driver,contact_detector,force_server', '--duration', '40',
                          '--domain-id', str(_domain + 5), '--localhost', '--record', str(bag),
                          '--enclave-root', '/haptic_anfis',
                          '--log-dir', str(tmp_path / 'logs')], cwd=ROOT, env=_env(),
                         stdout=out.open('w'), stderr=subprocess.STDOUT)
    try:
        _wait_line(out, r'ready after', 300)
        pid = int(_wait_line(out, r'started recorder +pid (\d+)', 5).group(1))
        time.sleep(2.0)
        os.kill(pid, signal.SIGKILL)
        assert p.wait(300) == 0, out.read_text()
    finally:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            p.wait(60)
    new = Path(f'{bag}.restart1')
    events = [json.loads(m.data) for *_, m in read_messages(new, ['/session/events'])]
    assert {'died', 'restarted'} <= {e['event'] for e in events if e.get('node') == 'recorder'}
    assert all(e.get('replayed') for e in events if e['event'] == 'died')
    assert sum(1 for _ in read_messages(new, ['/falcon/measured_cp'])) > 100
    assert cli(['bag', 'recover', str(bag)]) == 0
    assert sum(1 for _ in read_messages(bag, ['/falcon/measured_cp'])) > 0
