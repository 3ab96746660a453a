"""Cross-process tests: the node executables as subprocesses, talking over Fast DDS.

Each test uses its own ROS_DOMAIN_ID, localhost-only discovery, AMENT_PREFIX_PATH = the venv, and
does not pass the ROS wheels' re-exec guard (_ROS_WHEELS_BOOTSTRAP_COMPLETE) to the children.
Waits are generous (discovery can take seconds on a loaded machine); nothing asserts timings.
"""
from __future__ import annotations

import itertools
import math
import os
import subprocess
import time
from pathlib import Path

import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402

from haptic_anfis.realtime import processes as launcher  # noqa: E402
from haptic_anfis import interfaces as ifc  # noqa: E402
from haptic_anfis.nodes.runtime import LOOP_QOS  # noqa: E402

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[2]
BIN = launcher.BIN
_domains = itertools.count(120 + os.getpid() % 40 * 2)


def node_env(domain: int) -> dict:
    return launcher.node_env(domain, localhost=True)


def launch(name: str, args: list[str], domain: int, log: Path) -> subprocess.Popen:
    return launcher.start_node(name, args, env=node_env(domain), log=log.open('w'), cwd=ROOT)


stop = launcher.stop_node


class Observer:
    """A node in the test process on the test's domain: records the applied force."""

    def __init__(self, domain: int):
        from rclpy.context import Context
        from rclpy.experimental import EventsExecutor
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node('observer', context=self.ctx)
        self.forces: list[tuple[float, float, float]] = []
        self.node.create_subscription(WrenchStamped, ifc.TOPIC_APPLIED, self._on, 10)
        self.pose_pub = self.node.create_publisher(PoseStamped, ifc.TOPIC_POSE, LOOP_QOS)
        self.cmd_pub = self.node.create_publisher(WrenchStamped, ifc.TOPIC_COMMAND, LOOP_QOS)
        self.ex = EventsExecutor(context=self.ctx)
        self.ex.add_node(self.node)

    def _on(self, m):
        f = m.wrench.force
        self.forces.append((f.x, f.y, f.z))

    @property
    def force(self) -> float:
        return math.sqrt(sum(c * c for c in self.forces[-1])) if self.forces else math.nan

    def wait(self, cond, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.02)
            if cond():
                return True
        return False

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def test_graph_across_processes(tmp_path):
    """Press -> force, lift -> zero; NaN pose and NaN wrench survived; YAML + -p parameters take
    effect; killing the force server lets the watchdog zero the force."""
    domain = next(_domains)
    script = tmp_path / 'press.yaml'
    script.write_text(yaml.safe_dump({'loop': True, 'start_delay': 0.2, 'approach_height': 0.006,
                                      'pattern': [{'press': {'points': [[0.0, 0.0]], 'depth': 0.015,
                                                             'hold': 1.5}},
                                                  {'pause': {'duration': 1.0}}]}))
    params = tmp_path / 'driver.yaml'
    params.write_text(yaml.safe_dump({'falcon_driver': {'ros__parameters': {
        'palpation_script': str(script), 'measured_cf_every': 5, 'max_force': 8.0}}}))
    procs = {}
    obs = Observer(domain)
    try:
        procs['force_server'] = launch('force_server', [], domain, tmp_path / 'force_server.log')
        procs['contact_detector'] = launch('contact_detector', [], domain,
                                           tmp_path / 'contact_detector.log')
        # YAML (script, max_force 8.0) then -p override (max_force 2.5): the override wins.
        procs['falcon_driver'] = launch(
            'falcon_driver', ['--params-file', str(ROOT / 'config' / 'falcon_driver.yaml'),
                              '--params-file', str(params), '-p', 'max_force:=2.5'],
            domain, tmp_path / 'falcon_driver.log')

        def logs():
            return '\n'.join(f'--- {n}\n' + (tmp_path / f'{n}.log').read_text()[-3000:]
                             for n in procs)

        # 1. force appears while pressing (incl. discovery and numba cache loading) ...
        assert obs.wait(lambda: obs.force > 1.0, 90.0), 'no force while pressing\n' + logs()
        # ... clamped by the -p override, not the YAML's 8 N
        obs.wait(lambda: False, 1.0)
        assert max(math.sqrt(sum(c * c for c in f)) for f in obs.forces) <= 2.5 + 1e-9
        assert 'max force 2.5 N' in (tmp_path / 'falcon_driver.log').read_text()
        # 2. ... and vanishes when the hand lifts
        assert obs.wait(lambda: obs.force == 0.0, 30.0), 'force did not vanish\n' + logs()
        # 3. NaN pose and NaN wrench: logged, survived, the loop goes on
        bad_pose = PoseStamped()
        bad_pose.header.frame_id = 'tissue'
        bad_pose.pose.position.y = math.nan
        bad_cmd = WrenchStamped()
        bad_cmd.header.frame_id = 'tissue'
        bad_cmd.wrench.force.z = math.inf
        for _ in range(20):
            obs.pose_pub.publish(bad_pose)
            obs.cmd_pub.publish(bad_cmd)
            obs.wait(lambda: False, 0.02)
        assert obs.wait(lambda: obs.force > 1.0, 30.0), 'no force after NaN input\n' + logs()
        assert all(p.poll() is None for p in procs.values()), logs()
        # 4. watchdog: kill the force server while pressing -> force ramps to zero
        n = len(obs.forces)
        procs['force_server'].kill()
        procs['force_server'].wait(10)
        assert obs.wait(lambda: len(obs.forces) > n + 20 and obs.force == 0.0, 10.0), \
            'watchdog did not zero the force\n' + logs()
        assert obs.wait(lambda: False, 2.0) is False and obs.force == 0.0
        assert procs['falcon_driver'].poll() is None
    finally:
        for p in procs.values():
            stop(p)
        obs.close()
    text = (tmp_path / 'falcon_driver.log').read_text()
    assert 'rejected: non-finite force' in text
    assert 'bad pose' in (tmp_path / 'contact_detector.log').read_text()
    assert procs['falcon_driver'].returncode == 0, text[-3000:]


@pytest.mark.parametrize('node, args, match', [
    ('falcon_driver', ['-p', 'max_force:=-1.0'], 'max_force: -1.0: expected a finite value > 0'),
    ('falcon_driver', ['-p', 'rate:=1000'], 'rate: got 1000 (an integer), expected a double'),
    ('falcon_driver', ['-p', 'max_force:=1e9'], 'max_force: 1000000000.0: expected a finite '
     'value > 0 and <= 8.9 N'),
    ('falcon_driver', ['-p', 'watchdog_timeout:=1e9'], 'watchdog_timeout: 1000000000.0: '
     'expected a finite value >= 0.001 and <= 0.05 s'),
    ('falcon_driver', ['-p', 'rate:=1e9'], 'rate: 1000000000.0: expected a finite value >= 100 '
     'and <= 1000 Hz'),
    ('falcon_driver', ['-p', 'max_force:=lots'],
     "max_force: got 'lots' (a string), expected a double such as 8.9"),
    ('force_server', ['-p', 'modle_path:=x'], "unknown parameter 'modle_path'"),
    ('falcon_driver', ['-p', 'palpation_script:=/nonexistent.yaml'], 'nonexistent.yaml'),
    ('force_server', ['-p', 'model_path:=/nonexistent/model.json'], 'model.json'),
    ('contact_detector', ['-p', 'mesh_unit:=cm'], "mesh_unit: 'cm': expected one of"),
])
def test_bad_parameters_exit_nonzero_with_clear_message(tmp_path, node, args, match):
    domain = next(_domains)
    p = subprocess.run([str(BIN / node), '--ros-args', *args], env=node_env(domain), cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode != 0
    assert match in p.stderr, p.stderr[-2000:]


def test_launch_command_runs_the_graph_as_separate_processes(tmp_path, capfd):
    """`haptic-anfis launch`: one process per node, the recorder too; the bag shows the force the
    simulated hand met, and every node stops cleanly (exit 0) at the end of --duration."""
    from haptic_anfis.bag import read_messages
    from haptic_anfis.cli import main

    bag = tmp_path / 'bag'
    rc = main(['launch', '--nodes', 'falcon_driver,contact_detector,force_server', '--duration',
               '15', '--domain-id', str(next(_domains)), '--localhost', '--record', str(bag),
               '--log-dir', str(tmp_path / 'logs')])
    out = capfd.readouterr().out
    assert rc == 0, out
    for node in ('recorder', 'force_server', 'contact_detector', 'falcon_driver'):
        assert f'started {node}' in out and (tmp_path / 'logs' / f'{node}.log').is_file()
    assert out.count('exit code 0') == 4, out
    forces = [m.wrench.force.x for _, _, _, m in read_messages(bag, ['/falcon/servo_cf'])]
    assert len(forces) > 1000 and max(map(abs, forces)) > 0.5
    from haptic_anfis.bag import bag_info
    assert bag_info(bag).custom_data['case'] == 'default'   # for exam report


def test_launch_rejects_unknown_nodes_and_missing_files(tmp_path, capsys):
    from haptic_anfis.cli import main
    assert main(['launch', '--nodes', 'falcon_driver,teleporter']) == 1
    err = capsys.readouterr().err
    assert 'teleporter' in err and 'contact_detector' in err  # names the known nodes
    assert main(['launch', '--params-file', str(tmp_path / 'none.yaml')]) == 1
    assert 'no such file' in capsys.readouterr().err


def test_nodes_start_as_modules_when_no_console_script(tmp_path, monkeypatch):
    """On a colcon install the scripts are not beside the interpreter: nodes start as modules."""
    monkeypatch.setattr(launcher, 'BIN', tmp_path)  # no scripts here
    p = launcher.start_node('falcon_driver', ['-p', 'backend:=nonsense'],
                            env=node_env(next(_domains)), log=(tmp_path / 'log').open('w'))
    assert p.wait(60) == 1
    assert 'backend' in (tmp_path / 'log').read_text()
    with pytest.raises(ValueError, match='unknown node'):
        launcher.start_node('teleporter')
