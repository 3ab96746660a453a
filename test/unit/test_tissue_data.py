"""Physical sanity of the shipped FE dataset (haptic_anfis/data/default_forces.csv)."""
import numpy as np
import pytest

from haptic_anfis.tissue.dataset import DEFAULT_DATASET, load_dataset
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.scene import load_scene


@pytest.fixture(scope='module')
def data():
    ds = load_dataset(DEFAULT_DATASET)
    if not str(ds.provenance.get('kind', '')).startswith('FE'):
        pytest.skip('the shipped dataset is not the FE one')
    return ds


@pytest.fixture(scope='module')
def scene():
    return load_scene()


def _by_point(ds):
    out = {}
    for p in np.unique(ds.point):
        sel = ds.point == p
        order = np.argsort(ds.X[sel, 3])
        out[int(p)] = (ds.X[sel][order], ds.Y[sel][order])
    return out


def test_complete_and_made_from_the_shipped_scene(data, scene):
    assert data.provenance['scene_sha256'] == scene.sha256()
    assert data.provenance['failed_points'] == []
    n = len(loading_points(scene))
    assert len(data) == n * len(scene.depths)
    np.testing.assert_allclose(np.unique(data.X[:, 3]), scene.depths)


def test_force_positive_and_monotonic_in_depth(data):
    for X, Y in _by_point(data).values():
        assert np.all(Y[:, 0] > 0) and np.all(np.diff(Y[:, 0]) > 0)


def test_stiffer_over_the_tumour_than_at_its_mirror_point(data, scene):
    pts = _by_point(data)
    t = scene.tumours[0].centre
    yz = {p: X[0, 1:3] for p, (X, _) in pts.items()}
    over = min(yz, key=lambda p: np.hypot(*(yz[p] - t[1:])))
    mirror = min(yz, key=lambda p: np.hypot(*(yz[p] + yz[over])))
    ratio = pts[over][1][:, 0] / pts[mirror][1][:, 0]
    assert np.all(ratio > 1.0) and ratio[-1] > 1.03


def test_symmetric_far_from_the_tumour(data, scene):
    # The dome is symmetric under (y, z) -> (-y, -z); far from the tumour forces must be too.
    pts = _by_point(data)
    t = np.asarray(scene.tumours[0].centre[1:])
    yz = {p: X[0, 1:3] for p, (X, _) in pts.items()}
    checked = 0
    for p, v in yz.items():
        q = min(yz, key=lambda k: np.hypot(*(yz[k] + v)))
        if np.hypot(*(yz[q] + v)) > 1e-6 or min(np.hypot(*(v - t)), np.hypot(*(-v - t))) < 0.030:
            continue
        Fp, Fq = pts[p][1], pts[q][1]
        np.testing.assert_allclose(Fp[:, 0], Fq[:, 0], rtol=0.01)
        np.testing.assert_allclose(Fp[:, 1:], -Fq[:, 1:], atol=0.01 * Fp[:, :1].max())
        checked += 1
    assert checked >= 10


def test_lateral_forces_small_at_apex(data):
    pts = _by_point(data)
    apex = min(pts, key=lambda p: np.hypot(*pts[p][0][0, 1:3]))
    F = pts[apex][1]
    assert np.all(np.abs(F[:, 1:]) < 0.03 * F[:, :1])
