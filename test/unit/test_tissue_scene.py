"""Scene files: loading, SI conversion and clear validation errors."""
import copy

import numpy as np
import pytest
import yaml

from haptic_anfis.tissue.geometry import loading_points, surface_mesh, write_surface_mesh
from haptic_anfis.tissue.scene import DEFAULT_SCENE, SceneError, load_scene, parse_scene


@pytest.fixture(scope='module')
def raw():
    return yaml.safe_load(DEFAULT_SCENE.read_text())


def test_default_scene_loads_in_si():
    s = load_scene()
    assert s.radii == pytest.approx((0.045, 0.070, 0.070))
    assert s.probe_radius == pytest.approx(0.008)
    assert s.depths == pytest.approx((0.002, 0.005, 0.008, 0.012, 0.016))
    assert s.material.youngs == pytest.approx(33e3)
    assert s.tumours[0].youngs == pytest.approx(93e3)
    assert s.direction == 'axis'
    assert len(s.sha256()) == 64 and len(s.source_sha256) == 64


def test_default_loading_points_on_surface():
    s = load_scene()
    p = loading_points(s)
    assert 140 <= len(p) <= 160  # the paper used 153
    rx, ry, rz = s.radii
    np.testing.assert_allclose((p[:, 0] / rx) ** 2 + (p[:, 1] / ry) ** 2 + (p[:, 2] / rz) ** 2, 1.0)
    assert np.hypot(p[:, 1], p[:, 2]).max() <= s.palpable_radius + 1e-12


def _bad(raw, path, value):
    d = copy.deepcopy(raw)
    node = d
    for k in path[:-1]:
        node = node[k]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return d


@pytest.mark.parametrize('path, value, message', [
    (('breast', 'radii_mm'), [45, 70], 'list of 3'),
    (('material', 'youngs_kPa'), -5, 'must be > 0'),
    (('material', 'poisson'), 0.5, 'poisson'),
    (('material', 'colour'), 'pink', 'unknown key'),
    (('probe', 'direction'), 'sideways', 'axis'),
    (('loading', 'depths_mm'), [2, 5, 40], 'thickness'),
    (('loading', 'depths_mm'), [5, 2], 'increasing'),
    (('loading', 'palpable_radius_mm'), 66, 'edge of the breast'),
    (('tumours', 0, 'centre_mm'), [44, 0, 0], 'not inside the tissue'),
    (('tumours', 0, 'centre_mm'), [3, 0, 0], 'not inside the tissue'),
    (('tumours', 0, 'youngs_kPa'), 0, 'must be > 0'),
    (('loading', 'spacing_mm'), 'six', 'finite number'),
    (('mesh', 'edge_offset'), 1.5, 'edge_offset'),
    (('mesh', 'edge_offset'), -0.1, 'edge_offset'),
    (('probe',), KeyError, "missing required section 'probe'"),
])
def test_invalid_scenes_raise_clear_errors(raw, path, value, message):
    with pytest.raises(SceneError, match=message):
        parse_scene(_bad(raw, path, value))


def test_unknown_top_level_key(raw):
    with pytest.raises(SceneError, match='unknown key'):
        parse_scene({**raw, 'gravity': 9.81})


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match='does not exist'):
        load_scene(tmp_path / 'nope.yaml')


def test_surface_mesh_closed_and_in_mm(tmp_path):
    s = load_scene()
    m = surface_mesh(s.radii, subdivisions=3)
    assert m.is_watertight
    assert m.bounds[0][0] == pytest.approx(0.0, abs=1e-12)
    assert m.bounds[1] == pytest.approx([0.045, 0.070, 0.070], rel=1e-3)
    import trimesh

    path = write_surface_mesh(s, tmp_path / 'surf.stl')
    back = trimesh.load(path)
    assert back.bounds[1] == pytest.approx([45.0, 70.0, 70.0], rel=1e-3)


def test_cli_surface_and_errors(tmp_path, capsys):
    from haptic_anfis.cli import main

    assert main(['dataset', '--surface', str(tmp_path / 's.ply'), '--surface-units', 'm']) == 0
    assert (tmp_path / 's.ply').is_file()
    assert main(['dataset']) == 2
    bad = tmp_path / 'bad.yaml'
    bad.write_text(DEFAULT_SCENE.read_text().replace('youngs_kPa: 33', 'youngs_kPa: -33'))
    assert main(['dataset', str(bad), '--out', str(tmp_path / 'x.csv')]) == 1
    assert 'material.youngs_kPa: must be > 0' in capsys.readouterr().err
