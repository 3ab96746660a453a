"""In-process tests of the ROS 2 nodes (one rclpy context per test, EventsExecutor)."""
from __future__ import annotations

import json
import math
import time
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from haptic_anfis.tissue.dataset import DATA_DIR  # noqa: E402
from haptic_anfis import interfaces as ifc  # noqa: E402
from haptic_anfis.resources import config_file  # noqa: E402
from haptic_anfis.nodes.parameters import ParameterError  # noqa: E402
from haptic_anfis.nodes.runtime import LOOP_QOS  # noqa: E402
from haptic_anfis.nodes.graph import build_graph  # noqa: E402

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[2]
PRESS = {'loop': True, 'start_delay': 0.2, 'approach_height': 0.006, 'pattern': [
    {'press': {'points': [[0.0, 0.0]], 'depth': 0.012, 'hold': 0.8}}, {'pause': {'duration': 0.5}}]}


@pytest.fixture
def press_script(tmp_path):
    p = tmp_path / 'press.yaml'
    p.write_text(yaml.safe_dump(PRESS))
    return str(p)


@pytest.fixture
def graph_factory():
    made = []

    def make(driver=(), force=(), contact=(), visualizer=False, args=None):
        g = build_graph(args, visualizer=visualizer, overrides={
            'falcon_driver': list(driver), 'force_server': list(force),
            'contact_detector': list(contact)})
        made.append(g)
        return g
    yield make
    for g in made:
        g.shutdown()


def fnorm(f):
    return math.sqrt(f[0] ** 2 + f[1] ** 2 + f[2] ** 2)


def test_force_appears_when_pressing_and_vanishes_when_lifting(graph_factory, press_script):
    g = graph_factory(driver=[Parameter('palpation_script', value=press_script)], visualizer=True)
    viewer = rclpy.create_node('viewer', context=g.context)   # RViz: the visualizer draws for it
    g.extra.append(viewer)
    g.executor.add_node(viewer)
    viewer.create_subscription(MarkerArray, ifc.TOPIC_MARKERS, lambda m: None, 10)
    servo = g.driver.servo
    assert g.spin_for(20.0, lambda: fnorm(servo.force) > 1.0), 'no force while pressing'
    assert servo.force[0] > 0  # pushes the probe out of the body
    assert g.spin_for(20.0, lambda: servo.force == (0.0, 0.0, 0.0)), 'force did not vanish'
    s = g.summary()
    assert s['contact']['in_contact'] > 0 and s['force']['forces'] > 0
    assert s['loop']['latency_n'] > 0 and s['loop']['max_force_N'] <= 10.0
    assert s['visualizer']['marker_arrays'] > 0


def test_nan_pose_and_nan_wrench_are_survived(graph_factory, press_script):
    g = graph_factory(driver=[Parameter('palpation_script', value=press_script)])
    probe = rclpy.create_node('probe', context=g.context)
    g.extra.append(probe)
    g.executor.add_node(probe)
    contacts = []
    probe.create_subscription(JointState, ifc.TOPIC_CONTACT, contacts.append, 10)
    pose_pub = probe.create_publisher(PoseStamped, ifc.TOPIC_POSE, LOOP_QOS)
    cmd_pub = probe.create_publisher(WrenchStamped, ifc.TOPIC_COMMAND, LOOP_QOS)
    assert g.spin_for(20.0, lambda: contacts), 'graph not running'
    bad = PoseStamped()
    bad.header.frame_id = 'tissue'
    bad.pose.position.x = math.nan
    nan_wrench = WrenchStamped()
    nan_wrench.header.frame_id = 'tissue'
    nan_wrench.wrench.force.x = math.nan
    # The probe's publishers are new: keep publishing until discovery has matched them to the
    # contact detector and the driver (on a loaded 2-core machine that can take seconds).
    def both_rejected():
        return g.contact.n_bad > 0 and g.driver.safety.stats.rejected_nonfinite > 0

    end = time.monotonic() + 20.0
    while not both_rejected() and time.monotonic() < end:
        pose_pub.publish(bad)
        cmd_pub.publish(nan_wrench)
        g.spin_for(0.05, both_rejected)
    assert both_rejected(), (g.contact.n_bad, g.driver.safety.stats.rejected_nonfinite)
    assert g.driver.servo.running and g.driver.servo.errors == 0
    # the loop goes on and forces come back
    n = len(contacts)
    assert g.spin_for(20.0, lambda: len(contacts) > n + 100 and fnorm(g.driver.servo.force) > 1.0)
    assert all(len(c.position) == len(ifc.CONTACT_FIELDS) and list(c.name) ==
               list(ifc.CONTACT_FIELDS) for c in contacts[-10:])


def test_reload_service_swaps_model_and_keeps_it_on_bad_file(graph_factory, tmp_path, press_script):
    model = tmp_path / 'model.json'
    shutil.copy(DATA_DIR / 'default_model.json', model)
    g = graph_factory(force=[Parameter('model_path', value=str(model))],
                      driver=[Parameter('palpation_script', value=press_script)])
    client_node = rclpy.create_node('client', context=g.context)
    g.extra.append(client_node)
    g.executor.add_node(client_node)
    cli = client_node.create_client(Trigger, ifc.SERVICE_RELOAD)

    def call():
        fut = cli.call_async(Trigger.Request())
        assert g.spin_for(20.0, fut.done), 'no reply from reload'
        return fut.result()

    assert g.spin_for(10.0, cli.service_is_ready)
    old = g.force.model
    r = call()
    assert r.success and 'loaded' in r.message and g.force.model is not old
    good = g.force.model
    model.write_text('{"format": "not a model"')
    r = call()
    assert not r.success and 'kept the previous model' in r.message and g.force.model is good
    # still rendering forces with the kept model
    assert g.spin_for(20.0, lambda: fnorm(g.driver.servo.force) > 1.0)


@pytest.mark.parametrize('node, params, match', [
    ('falcon_driver', [Parameter('max_force', value=-1.0)], 'max_force'),
    ('falcon_driver', [Parameter('backend', value='falcon_usb')], 'backend'),
    ('falcon_driver', [Parameter('workspace_offset', value=[0.0, 0.0])], 'workspace_offset'),
    ('contact_detector', [Parameter('mesh_unit', value='cm')], 'mesh_unit'),
    ('contact_detector', [Parameter('dome_radii', value=[0.045, 0.0, 0.07])], 'dome_radii'),
])
def test_bad_parameters_rejected_in_process(node, params, match):
    with pytest.raises(ParameterError, match=match):
        build_graph(None, visualizer=False, overrides={node: params})


def test_config_yaml_matches_declared_parameters():
    import importlib
    for node in ('falcon_driver', 'contact_detector', 'force_server', 'trainer', 'visualizer'):
        mod = importlib.import_module(f'haptic_anfis.nodes.{node}')
        doc = yaml.safe_load((ROOT / 'config' / f'{node}.yaml').read_text())
        values = doc[node]['ros__parameters']
        declared = mod.PARAMS + getattr(mod, 'CASE_PARAMS', [])  # the case ones are writable
        assert list(values) == [p.name for p in declared], node
        for p in declared:
            assert values[p.name] == p.default and type(values[p.name]) is type(p.default), p.name
            assert p.description
    assert config_file('palpation.yaml').is_file()


def test_trainer_trains_writes_and_reloads(tmp_path):
    from haptic_anfis.nodes.force_server import ForceServer
    from haptic_anfis.nodes.executor import make_executor
    from haptic_anfis.nodes.trainer import Trainer
    from rclpy.context import Context
    model = tmp_path / 'model.json'
    shutil.copy(DATA_DIR / 'default_model.json', model)
    ctx = Context()
    rclpy.init(context=ctx)
    try:
        fs = ForceServer(context=ctx, parameter_overrides=[Parameter('model_path', value=str(model))])
        tr = Trainer(context=ctx, parameter_overrides=[
            Parameter('model_path', value=str(model)), Parameter('structure', value='2-2-2'),
            Parameter('epochs', value=2)])
        progress = []
        tr.create_subscription(__import__('std_msgs.msg', fromlist=['String']).String,
                               '~/progress', lambda m: progress.append(m.data), 10)
        ex = make_executor(ctx)
        ex.add_node(fs)
        ex.add_node(tr)
        before = model.stat().st_mtime_ns
        ok, msg = tr.start_training()
        assert ok and 'started' in msg
        assert not tr.start_training()[0]  # one at a time
        import time
        end = time.monotonic() + 120
        while time.monotonic() < end and not tr.results:
            ex.spin_once(timeout_sec=0.05)
        assert tr.results and tr.results[-1][0], tr.results
        assert fs.reloads == 1 and model.stat().st_mtime_ns != before
        assert fs.model.structures_ == [(2, 2, 2)] * 3
        end = time.monotonic() + 2
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert any('wrote' in p for p in progress)
        ex.shutdown()
        fs.destroy_node()
        tr.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_sim_command_prints_loop_statistics(capfd, tmp_path):
    from haptic_anfis.cli import main
    bag = tmp_path / 'session'
    trace = tmp_path / 'ticks.npz'
    assert main(['sim', '--duration', '3', '--no-viz', '--record', str(bag), '--json',
                 '--trace', str(trace)]) == 0
    out = capfd.readouterr().out
    for key in ('servo loop', 'Hz', 'deadline misses', 'p50', 'p99', 'max applied', 'poses in contact',
                'recorded'):
        assert key in out, out
    last = json.loads(out.strip().splitlines()[-1])  # --json: the last line is one JSON object
    for key in ('rate_hz', 'latency_p50_ms', 'latency_p99_ms', 'latency_max_ms', 'deadline_misses',
                'cycles', 'max_force_n', 'contact_s', 'recorded_messages'):
        assert key in last, last
    assert last['cycles'] > 1000 and 0.0 <= last['contact_s'] <= last['seconds']
    assert last['recorded_messages'] > 0
    from haptic_anfis.bag import bag_info
    assert bag_info(bag).custom_data['case'] == 'default'   # for exam report
    assert (bag / 'metadata.yaml').is_file()
    assert main(['sim', '--duration', '1', '--record', str(bag)]) == 1  # exists: clear error
    assert 'exists already' in capfd.readouterr().err
    # --trace keeps the tick trace sim --json reported; loop --from reports a window of it
    assert last['periods_lost'] is not None and trace.is_file()
    assert main(['loop', str(trace), '--from', '1', '--json']) == 0
    window = json.loads(capfd.readouterr().out.strip().splitlines()[-1])
    assert window['from_s'] == 1.0 and 'latency_p99_ms' in window['whole_run']
    # the window is the ticks from 1 s after the first (not a count that assumed 1 kHz in the
    # first second: a loaded machine's first second had 826 ticks)
    from haptic_anfis.device.trace import DISABLED, load_trace
    rows, meta = load_trace(trace)
    t = rows[rows[:, 7] != DISABLED, 0]
    # ticks line up with a bag's (wall-clock) receive times
    assert abs(meta['realtime_minus_monotonic_s'] - (time.time() - time.monotonic())) < 1.0
    from haptic_anfis.nodes.falcon_driver import PARAMS
    from haptic_anfis.nodes.parameters import default_of
    assert meta['model_hold_time'] == default_of(PARAMS, 'model_hold_time')
    assert 0 < window['ticks'] == int(np.sum(t >= t[0] + 1.0)) < len(t)
    assert main(['sim', '--duration', '1', '--trace', str(trace)]) == 1   # never overwritten
    assert '--trace' in capfd.readouterr().err
