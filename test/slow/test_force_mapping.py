"""The tissue -> device force mapping (haptic_anfis.cases.force_mapping): one scale per case
that puts the case's largest trained FE force at 85 % of the clamp, carried by the session to the
driver unless the user sets force_scale, shown by `cases list` and recorded in the bag."""
import json

import numpy as np
import pytest

from haptic_anfis.cases import library
from haptic_anfis.cases.force_mapping import (HEADROOM, case_force_mapping, fe_peak_force,
                                              mapping_for)
from haptic_anfis.device.falcon import RATED_FORCE
from haptic_anfis.session.spec import SessionSpec


def test_the_peak_is_read_over_the_palpable_disc_at_the_deepest_depth():
    X = np.array([[0.04, 0.0, 0.0, 0.008], [0.04, 0.0, 0.0, 0.016], [0.04, 0.03, 0.0, 0.016],
                  [0.03, 0.05, 0.0, 0.016]])   # the last one lies outside a 42 mm disc
    Y = np.array([[30.0, 0, 0], [10.0, 0, 0], [12.0, 5.0, 0], [99.0, 0, 0]])
    peak, depth = fe_peak_force(X, Y, 0.042)
    assert depth == 0.016 and peak == pytest.approx(13.0)
    with pytest.raises(ValueError, match='within the palpable radius 10 mm'):
        fe_peak_force(X[3:], Y[3:], 0.010)


def test_the_scale_puts_the_peak_at_the_headroom_and_never_amplifies():
    m = mapping_for('c', 20.0, 0.016)
    assert m.force_scale * 20.0 == pytest.approx(HEADROOM * RATED_FORCE)
    assert mapping_for('soft', 2.0, 0.016).force_scale == 1.0
    assert 'x0.378 (20.0 N at 16 mm -> 7.6 N of 8.9 N)' == m.text()
    for bad, what in ((0.0, 'FE peak force'), (float('nan'), 'FE peak force')):
        with pytest.raises(ValueError, match=what):
            mapping_for('c', bad, 0.016)
    with pytest.raises(ValueError, match='max_force'):
        mapping_for('c', 10.0, 0.016, max_force=-1.0)


def test_every_ready_case_fits_under_the_clamp_at_its_deepest_trained_depth():
    from haptic_anfis.tissue.dataset import load_dataset
    for case in library().ready():
        m = case_force_mapping(case)
        ds = load_dataset(case.dataset_path)
        r = np.hypot(ds.X[:, 1], ds.X[:, 2]) <= case.scene.palpable_radius + 1e-9
        top = np.linalg.norm(ds.Y[r], axis=1).max()
        assert m.force_scale * top <= HEADROOM * RATED_FORCE + 1e-9, case.name
        assert m.depth_m == pytest.approx(ds.X[:, 3].max())


def test_the_session_sets_the_drivers_scale_from_its_case_unless_the_user_does():
    case = library().get('lib_m_dense_idc25_d15')
    want = case_force_mapping(case).force_scale
    assert SessionSpec(case=case.name).driver_arguments() == [
        '-p', f'falcon_driver:force_scale:={want!r}']
    drawn = library().random(5)
    assert SessionSpec(random_case=True, seed=5).driver_arguments()[1].endswith(
        repr(case_force_mapping(drawn).force_scale))
    # the default scene without a case: the default dataset's mapping
    assert SessionSpec().force_mapping().case == 'default'
    assert SessionSpec(ros_args=('-p', 'force_scale:=1.0')).driver_arguments() == []
    assert SessionSpec(ros_args=('-p', 'falcon_driver:force_scale:=0.5')).driver_arguments() == []
    low = SessionSpec(case=case.name, ros_args=('-p', 'max_force:=4.0')).force_mapping()
    assert low.max_force_n == 4.0 and low.force_scale == pytest.approx(want * 4.0 / RATED_FORCE)
    assert SessionSpec(nodes=('contact_detector', 'force_server')).driver_arguments() == []
    from haptic_anfis.resources import config_file
    shipped = SessionSpec(case=case.name, params_files=(str(config_file('falcon_driver.yaml')),))
    assert shipped.force_mapping().force_scale == pytest.approx(want)   # its 1.0 is the default


def test_cases_list_and_the_bag_record_the_mapping(capsys):
    from haptic_anfis.cli import main
    from haptic_anfis.nodes.recorder import _force_mapping_data
    assert main(['cases', 'list', '--json', '--no-timing']) == 0
    rows = {r['name']: r for r in json.loads(capsys.readouterr().out)}
    m = rows['lib_m_dense_idc20_d12']['force_mapping']
    assert m['force_scale'] == pytest.approx(
        case_force_mapping(library().get('lib_m_dense_idc20_d12')).force_scale)
    assert json.loads(_force_mapping_data('lib_m_dense_idc20_d12')['force_mapping']) == m
    assert _force_mapping_data('unknown') == {}


def test_a_session_graph_renders_its_case_at_the_case_scale():
    from haptic_anfis.session.one_process import open_graph
    spec = SessionSpec(nodes=('falcon_driver', 'contact_detector', 'force_server'),
                       case='lib_m_dense_idc25_d15')
    g = open_graph(spec, visualizer=False)
    try:
        want = case_force_mapping(library().get('lib_m_dense_idc25_d15')).force_scale
        assert g.driver.mapping.force_scale == pytest.approx(want)
    finally:
        g.shutdown()
