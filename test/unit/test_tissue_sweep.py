"""Parallel resumable sweep, pluggable executors, and physical sanity of FE forces (coarse mesh)."""
import concurrent.futures as cf
import dataclasses
import json
import threading

import numpy as np
import pytest

from haptic_anfis.tissue.dataset import load_dataset, save_dataset
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.scene import load_scene
from haptic_anfis.tissue.sweep import run_sweep


@pytest.fixture(scope='module')
def scene():
    # Coarse mesh, three depths: the physics checks below, in well under a minute.
    return dataclasses.replace(load_scene(), depths=(0.002, 0.005, 0.008))


def _ids(scene):
    pts = loading_points(scene)
    t = scene.tumours[0].centre
    over = int(np.argmin(np.hypot(pts[:, 1] - t[1], pts[:, 2] - t[2])))
    # The dome is symmetric under (y, z) -> (-y, -z): the mirror point differs only by the tumour.
    mirror = int(np.argmin(np.hypot(pts[:, 1] + pts[over, 1], pts[:, 2] + pts[over, 2])))
    centre = int(np.argmin(np.hypot(pts[:, 1], pts[:, 2])))
    return over, mirror, centre


@pytest.fixture(scope='module')
def coarse_run(scene, tmp_path_factory):
    work = tmp_path_factory.mktemp('sweep')
    ids = _ids(scene)
    res = run_sweep(scene, work, coarse=True, workers=2, indices=ids, progress=False)
    return ids, res, work


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
def test_sweep_records_every_depth(coarse_run, scene):
    ids, res, work = coarse_run
    assert not res.failed
    assert len(res.dataset) == 3 * len(scene.depths)
    assert sorted(set(res.dataset.point.tolist())) == sorted(ids)
    np.testing.assert_allclose(np.unique(res.dataset.X[:, 3]), scene.depths)
    for i in ids:
        assert (work / f'point_{i:04d}.json').is_file()
    prov = res.dataset.provenance
    assert prov['scene_sha256'] == scene.sha256() and prov['mesh']['ndof_min'] > 1000
    assert 'felupe' in prov['solver'] and prov['wall_time_s']['sum_over_points'] > 0


def test_force_monotonic_in_depth_and_pushes_out(coarse_run):
    _, res, _ = coarse_run
    ds = res.dataset
    for p in np.unique(ds.point):
        fx = ds.Y[ds.point == p, 0][np.argsort(ds.X[ds.point == p, 3])]
        assert np.all(fx > 0) and np.all(np.diff(fx) > 0)


def test_tumour_raises_force_over_it(coarse_run):
    (over, mirror, _), res, _ = coarse_run
    ds = res.dataset
    f_over = ds.Y[ds.point == over, 0]
    f_mirror = ds.Y[ds.point == mirror, 0]
    assert np.all(f_over > f_mirror)
    assert f_over[-1] / f_mirror[-1] - 1 > 0.02  # a few per cent at 8 mm, more at depth


def test_lateral_forces_small_at_symmetric_apex(coarse_run):
    (_, _, centre), res, _ = coarse_run
    ds = res.dataset
    F = ds.Y[ds.point == centre]
    # Only the off-centre tumour breaks the symmetry at the apex.
    assert np.all(np.abs(F[:, 1:]) < 0.03 * F[:, :1])


def test_dataset_roundtrip(coarse_run, tmp_path):
    _, res, _ = coarse_run
    path = save_dataset(res.dataset, tmp_path / 'd.csv')
    back = load_dataset(path)
    np.testing.assert_array_equal(back.Y, res.dataset.Y)
    assert back.provenance['scene'] == 'default'


def _fake_task(scene, index, point, coarse):
    return {'point': index, 'surface_point_m': point, 'status': 'ok', 'depths_m': [0.002],
            'forces_N': [[1.0 + index, 0.0, 0.0]], 'ndof': 3, 'ncells': 1, 'probe_edge_m': 1e-3,
            'wall_time_s': 0.0, 'linear_solver': 'fake'}


def test_resume_after_interrupt_loses_only_points_in_flight(scene, tmp_path):
    calls = []
    lock = threading.Lock()

    def flaky(scene, index, point, coarse):
        with lock:
            calls.append(index)
        if index == 3:
            raise KeyboardInterrupt  # Ctrl-C while point 3 is in flight
        return _fake_task(scene, index, point, coarse)

    with cf.ThreadPoolExecutor(max_workers=1) as ex:  # any Executor plugs in
        with pytest.raises(KeyboardInterrupt):
            run_sweep(scene, tmp_path, indices=[1, 2, 3, 4], executor=ex, task=flaky,
                      progress=False)
    done = sorted(int(p.stem.split('_')[1]) for p in tmp_path.glob('point_*.json'))
    assert done == [1, 2]
    calls.clear()
    with cf.ThreadPoolExecutor(max_workers=2) as ex:
        res = run_sweep(scene, tmp_path, indices=[1, 2, 3, 4], executor=ex, task=_fake_task,
                        progress=False)
    assert res.dataset.Y[:, 0].tolist() == [2.0, 3.0, 4.0, 5.0]
    # nothing already persisted was solved again
    res2 = run_sweep(scene, tmp_path, indices=[1, 2, 3, 4], task=lambda *a: 1 / 0, progress=False)
    assert len(res2.dataset) == 4


def test_work_dir_of_another_scene_is_refused(scene, tmp_path):
    run_sweep(scene, tmp_path, indices=[0], executor=cf.ThreadPoolExecutor(1), task=_fake_task,
              progress=False)
    other = dataclasses.replace(scene, depths=(0.002,))
    with pytest.raises(ValueError, match='another scene'):
        run_sweep(other, tmp_path, indices=[0], task=_fake_task, progress=False)
    assert json.loads((tmp_path / 'manifest.json').read_text())['scene_sha256'] == scene.sha256()


class _DaskLikeFuture:
    """Not a concurrent.futures.Future: only .result(), as third-party executors may return."""

    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


class _DaskLikeExecutor:
    def submit(self, fn, *args):
        return _DaskLikeFuture(fn(*args))


def test_executor_without_native_futures(scene, tmp_path):
    res = run_sweep(scene, tmp_path, indices=[5, 6], executor=_DaskLikeExecutor(),
                    task=_fake_task, progress=False)
    assert res.dataset.point.tolist() == [5, 6]


def test_normal_direction_pushes_along_the_surface_normal(scene):
    from haptic_anfis.tissue.fe import solve_scene_point
    from haptic_anfis.tissue.geometry import surface_normals

    s = dataclasses.replace(scene, direction='normal', depths=(0.002,))
    pts = loading_points(s)
    p = pts[int(np.argmax(np.hypot(pts[:, 1], pts[:, 2])))]  # steepest point
    res = solve_scene_point(s, p, coarse=True)
    n = surface_normals(p[None], s.radii)[0]
    f = res.forces[0]
    assert f @ n > 0.9 * np.linalg.norm(f)  # the tissue pushes the probe back out along n
    assert res.info['direction'] == pytest.approx((-n).tolist())


# --- skin displacement profiles (issue 16) ---

def test_sweep_records_skin_displacement_beside_forces(coarse_run, scene, tmp_path):
    from haptic_anfis.tissue.displacement import (RHO_OVER_A, DisplacementDataError,
                                                  displacement_path, load_displacements,
                                                  save_displacements)

    ids, res, _ = coarse_run
    disp = res.displacements
    assert disp is not None and sorted(disp.point.tolist()) == sorted(ids)
    assert disp.meta['dataset_sha256'] == res.dataset.sha256()
    np.testing.assert_allclose(disp.depths, scene.depths)
    axial0 = disp.coeffs[:, :, :, 0, 0]  # (P, D, K): harmonic 0 of the axial displacement
    inside = RHO_OVER_A <= 0.9  # inside the meshed footprint (bonded): exactly the depth
    want = np.broadcast_to(disp.depths[None, :, None], axial0[:, :, inside].shape)
    np.testing.assert_allclose(axial0[:, :, inside], want, atol=1e-9)
    assert np.all(np.abs(disp.coeffs[:, :, inside, 1:]) < 1e-9)
    assert np.all(np.abs(disp.coeffs[:, :, inside, 0, 1:]) < 1e-9)
    # the dent decays: at 3 probe radii under a quarter of the depth, monotone across the edge
    k3 = int(np.flatnonzero(RHO_OVER_A == 3.2)[0])
    assert np.all(axial0[:, :, k3] < 0.25 * disp.depths[None])
    edge = (RHO_OVER_A >= 1.0) & (RHO_OVER_A <= 2.0)
    assert np.all(np.diff(axial0[:, :, edge], axis=2) < 0)
    assert np.all(disp.truncation_rms < 0.02 * disp.depths[None])  # harmonics 0..2 suffice
    path = save_displacements(disp, displacement_path(tmp_path / 'd.csv'))
    assert path.name == 'd.displacement.npz'
    back = load_displacements(path, dataset_sha256=res.dataset.sha256())
    np.testing.assert_allclose(back.coeffs, disp.coeffs, atol=1e-9)  # float32, m
    with pytest.raises(DisplacementDataError, match='belongs to dataset'):
        load_displacements(path, dataset_sha256='0' * 64)


def test_resumed_sweep_solves_records_without_displacement_again(coarse_run, scene):
    ids, res, work = coarse_run
    f = work / f'point_{ids[2]:04d}.json'
    rec = json.loads(f.read_text())
    rec.pop('displacement')  # a work file written before displacement output existed
    f.write_text(json.dumps(rec))
    again = run_sweep(scene, work, coarse=True, workers=1, indices=ids, progress=False)
    assert 'displacement' in json.loads(f.read_text())
    np.testing.assert_allclose(again.dataset.Y, res.dataset.Y, rtol=1e-9)
    np.testing.assert_allclose(again.displacements.coeffs, res.displacements.coeffs, atol=1e-12)


def test_displacements_ship_beside_an_equal_force_csv(coarse_run, tmp_path):
    from haptic_anfis.tissue.displacement import (DisplacementDataError, displacement_path,
                                                  load_displacements, save_displacements,
                                                  ship_beside)

    _, res, _ = coarse_run
    new = save_dataset(res.dataset, tmp_path / 'new.csv')
    save_displacements(res.displacements, displacement_path(new))
    old_ds = dataclasses.replace(res.dataset, Y=res.dataset.Y * (1 + 1e-13))  # float noise
    old = save_dataset(old_ds, tmp_path / 'old.csv')
    path = ship_beside(new, old)
    assert path == displacement_path(old)
    back = load_displacements(path, dataset_sha256=old_ds.sha256())
    assert back.meta['forces_max_rel_diff_vs_dataset'] < 1e-12
    other = save_dataset(dataclasses.replace(res.dataset, Y=res.dataset.Y * 1.01),
                         tmp_path / 'other.csv')
    with pytest.raises(DisplacementDataError, match='forces differ'):
        ship_beside(new, other)
