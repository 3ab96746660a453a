"""Switching case on a running one-process graph: no crash, no spike; bad names rejected; the
nodes' case parameters and the sim / launch flags."""
from __future__ import annotations

import importlib
import math
import shutil

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from haptic_anfis.cases import CaseError, CaseLibrary  # noqa: E402
library_module = importlib.import_module('haptic_anfis.cases.library')  # (the package's
# `library` attribute is the function of that name)
from haptic_anfis.tissue.dataset import DATA_DIR  # noqa: E402
from haptic_anfis import interfaces as ifc  # noqa: E402
from haptic_anfis.nodes.runtime import LOOP_QOS  # noqa: E402
from haptic_anfis.nodes.graph import build_graph  # noqa: E402
from haptic_anfis.tissue.scene import SCENE_DIR  # noqa: E402

pytestmark = pytest.mark.ros
#: press 14 mm at the apex, hold, lift, repeat: the switches land mid-press
PRESS = {'loop': True, 'start_delay': 0.1, 'approach_height': 0.004, 'pattern': [
    {'press': {'points': [[0.0, 0.0]], 'depth': 0.014, 'hold': 0.6}}, {'pause': {'duration': 0.2}}]}
MAX_FORCE = 8.9   # the Falcon's rated force, the bound haptic_anfis.device.limits sets


@pytest.fixture
def small_case_library(tmp_path, monkeypatch):
    """A library with the default case and 'small' (35 x 60 x 60 mm breast: the probe is 10 mm
    less deep after a switch from the default 45 mm dome, or 10 mm deeper switching back),
    using the default model (what matters here is the swap, not the model's accuracy)."""
    from haptic_anfis.cases.generate import write_case_mesh

    sd, dd = tmp_path / 'scenes', tmp_path / 'data'
    sd.mkdir()
    (dd / 'cases' / 'small').mkdir(parents=True)
    shutil.copy(SCENE_DIR / 'default.yaml', sd / 'default.yaml')
    shutil.copy(SCENE_DIR / 'normal_fatty_small.yaml', sd / 'small.yaml')
    for f in ('default_forces.csv', 'default_forces.json', 'default_model.json',
              'default_surface.stl'):
        shutil.copy(DATA_DIR / f, dd / f)
    shutil.copy(DATA_DIR / 'default_model.json', dd / 'cases' / 'small' / 'model.json')
    lib = CaseLibrary(sd, dd, work_root=tmp_path / 'work')
    write_case_mesh(lib.get('small'))
    monkeypatch.setattr(library_module, 'library', lambda: lib)
    return lib


def _graph(tmp_path, case=''):
    script = tmp_path / 'press.yaml'
    script.write_text(yaml.safe_dump(PRESS))
    over = [Parameter('case', value=case)]
    return build_graph(None, visualizer=True, overrides={
        'falcon_driver': [Parameter('palpation_script', value=str(script)),
                          Parameter('max_force', value=MAX_FORCE)],
        'force_server': over, 'contact_detector': over, 'visualizer': over})


def _set_case(g, name):
    results = [n.set_parameters([Parameter('case', value=name)])[0]
               for n in (g.contact, g.force, g.visualizer)]
    return results


def test_case_switch_keeps_force_finite_and_clamped(small_case_library, tmp_path):
    g = _graph(tmp_path)
    try:
        probe = rclpy.create_node('probe', context=g.context)
        g.extra.append(probe)
        g.executor.add_node(probe)
        commands, applied = [], []
        probe.create_subscription(WrenchStamped, ifc.TOPIC_COMMAND, commands.append, LOOP_QOS)
        probe.create_subscription(WrenchStamped, 'falcon/measured_cf', applied.append, 100)
        servo = g.driver.servo
        forces = []  # the force the servo thread applies, sampled between callbacks

        def watch():
            forces.append(tuple(servo.force))
            return False
        assert g.spin_for(20.0, lambda: watch() or math.hypot(*servo.force) > 1.0), 'no force'
        for name in ('small', 'default', 'small'):
            mesh_before = g.contact.detector
            assert all(r.successful for r in _set_case(g, name)), name
            assert g.contact.detector is not mesh_before
            # The first force after the swap is zero (the case_ramp starts there).
            assert g.force._ramp_t0 is not None
            g.spin_for(3.0, watch)
        assert g.force.model_path == small_case_library.get('small').model_path
        # bad name: rejected, the old case stays, the loop goes on
        bad = _set_case(g, 'no_such_case')
        assert not any(r.successful for r in bad) and 'unknown case' in bad[0].reason
        assert g.contact.params['mesh_path'] == str(small_case_library.get('small').mesh_path)
        n = len(commands)
        assert g.spin_for(30.0, lambda: watch() or len(commands) > n + 50), 'loop stopped'
        assert g.driver.servo.running and g.driver.servo.errors == 0
        F = np.array([[c.wrench.force.x, c.wrench.force.y, c.wrench.force.z] for c in commands])
        A = np.array(forces + [(m.wrench.force.x, m.wrench.force.y, m.wrench.force.z)
                               for m in applied])
        assert np.all(np.isfinite(F)) and np.all(np.isfinite(A))
        assert np.linalg.norm(A, axis=1).max() <= MAX_FORCE + 1e-9
        assert np.linalg.norm(A, axis=1).max() > 1.0  # it did press throughout
        assert g.summary()['loop']['max_force_N'] <= MAX_FORCE
    finally:
        g.shutdown()


def test_random_case_and_bad_case_parameters(small_case_library, tmp_path):
    from haptic_anfis.nodes.parameters import ParameterError  # noqa: F401

    with pytest.raises(CaseError, match="unknown case 'nope'"):
        _graph(tmp_path, case='nope')
    g = build_graph(None, visualizer=False, overrides={
        'force_server': [Parameter('random_case_seed', value=1)],
        'contact_detector': [Parameter('random_case_seed', value=1)]})
    try:
        drawn = small_case_library.random(1)
        assert g.force.model_path == drawn.model_path
        assert g.contact.params['mesh_path'] == str(drawn.mesh_path)
    finally:
        g.shutdown()


def test_visualizer_hides_lesions_unless_asked(small_case_library, tmp_path):
    g = build_graph(None, visualizer=True, overrides={'visualizer': [
        Parameter('case', value='default')]})
    try:
        assert g.visualizer.tumours == []
        g.visualizer.set_parameters([Parameter('case', value='small')])
        assert g.visualizer.tumours == []
    finally:
        g.shutdown()
    g = build_graph(None, visualizer=True, overrides={'visualizer': [
        Parameter('case', value='default'), Parameter('show_tumours', value=True)]})
    try:
        assert len(g.visualizer.tumours) == 1
        assert g.visualizer.tumours[0].pose.position.y == pytest.approx(0.015)
        g.visualizer.set_parameters([Parameter('case', value='small')])
        assert g.visualizer.tumours == []  # the small normal breast has no lesion
    finally:
        g.shutdown()


def test_sim_and_launch_case_flags(small_case_library):
    import argparse

    from haptic_anfis.cases.library import add_case_arguments, case_node_arguments

    p = argparse.ArgumentParser()
    add_case_arguments(p)
    assert case_node_arguments(p.parse_args([])) == []
    assert case_node_arguments(p.parse_args(['--case', 'small'])) == ['-p', 'case:=small']
    assert case_node_arguments(p.parse_args(['--random-case', '--seed', '4'])) == \
        ['-p', 'random_case_seed:=4']
    for bad, msg in ((['--case', 'nope'], 'unknown case'), (['--random-case'], 'needs --seed'),
                     (['--seed', '3'], 'for --random-case'),
                     (['--case', 'small', '--random-case', '--seed', '1'], 'not both')):
        with pytest.raises(CaseError, match=msg):
            case_node_arguments(p.parse_args(bad))
    from haptic_anfis.cli import main

    assert main(['sim', '--case', 'nope', '--duration', '1']) == 1


def test_force_is_zero_at_the_swap_and_ramps_up(small_case_library, tmp_path):
    """Deterministic, one node: a contact right after the switch gives zero force, then the
    force grows over case_ramp to the model's."""
    from sensor_msgs.msg import JointState

    g = _graph(tmp_path)
    try:
        fs = g.force
        msg = JointState()
        msg.position = [0.045, 0.0, 0.0, 0.008, -1.0, 0.0, 0.0, 1.0, 0.0]
        out = []
        fs.pub.publish = lambda m: out.append((m.wrench.force.x, m.wrench.force.y,
                                               m.wrench.force.z))
        fs._on_contact(msg)
        full = out[-1][0]
        assert full > 1.0
        assert fs.set_parameters([Parameter('case', value='small')])[0].successful
        fs._on_contact(msg)
        assert out[-1] == (0.0, 0.0, 0.0)
        import time
        time.sleep(0.25)
        fs._on_contact(msg)
        mid = out[-1][0]
        time.sleep(0.4)
        fs._on_contact(msg)
        assert 0.0 < mid < out[-1][0] and fs._ramp_t0 is None  # ramped, then done
    finally:
        g.shutdown()


def test_a_case_switch_and_a_reload_run_off_real_time_priority(small_case_library, tmp_path,
                                                               monkeypatch):
    """Loading a case computes for hundreds of milliseconds without blocking: never at real-time
    priority (it would hold a core, and rtkit's run-time limit would end the node)."""
    import contextlib

    from haptic_anfis.nodes import _case, force_server
    state = {'off': False, 'loads_off': []}

    @contextlib.contextmanager
    def off():
        state['off'] = True
        try:
            yield
        finally:
            state['off'] = False
    load = force_server.load_model

    def watched(params):
        state['loads_off'].append(state['off'])
        return load(params)
    monkeypatch.setattr(_case, 'off_realtime', off)
    monkeypatch.setattr(force_server, 'off_realtime', off)
    monkeypatch.setattr(force_server, 'load_model', watched)
    g = _graph(tmp_path)
    try:
        assert g.force.set_parameters([Parameter('case', value='small')])[0].successful
        assert g.force.reload()[0]
    finally:
        g.shutdown()
    # the first load builds the node (before it is raised); the switch and the reload after
    assert state['loads_off'] == [False, True, True] and not state['off']
