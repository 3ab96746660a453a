"""The case library: lookup and errors, random draw, and a tiny coarse case generated end to end
(FE sweep -> dataset -> mesh -> model -> load -> predict), on a process pool and on dask."""
import json
import shutil

import numpy as np
import pytest
import yaml

from haptic_anfis.cases import CaseError, CaseLibrary, library
from haptic_anfis.cases.generate import generate_case
from haptic_anfis.cases.summary import case_summary, lesion_contrast
from haptic_anfis.tissue.dataset import load_dataset
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.scene import SCENE_DIR, SceneError, load_scene, parse_scene

#: Few points and depths, coarse mesh: the whole FE sweep in well under a minute.
TINY = {
    'name': 'tiny', 'description': 'test case: one lesion, 13 base points',
    'breast': {'radii_mm': [45, 70, 70]},
    'material': {'youngs_kPa': 33, 'poisson': 0.499},
    'tumours': [{'name': 'idc', 'kind': 'malignant', 'position_mm': [15, 0], 'depth_mm': 14,
                 'radius_mm': 7, 'youngs_kPa': 93}],
    'probe': {'diameter_mm': 16},
    'loading': {'spacing_mm': 15, 'palpable_radius_mm': 30, 'refine_spacing_mm': 7.5,
                'refine_margin_mm': 1, 'depths_mm': [2, 5, 8], 'max_step_mm': 3},
    'mesh': {'probe_cells': 4, 'coarse_probe_cells': 2, 'edge_offset': 0.2, 'edge_refine': 0},
}
PARAMS = {'structure': (2, 2, 2), 'epochs': 10, 'search_folds': 1, 'seed': 0}


def _library(tmp_path, scenes: dict) -> CaseLibrary:
    sd, dd = tmp_path / 'scenes', tmp_path / 'data'
    sd.mkdir()
    dd.mkdir()
    for name, doc in scenes.items():
        (sd / f'{name}.yaml').write_text(yaml.safe_dump(doc))
    return CaseLibrary(sd, dd, work_root=tmp_path / 'work')


@pytest.fixture(scope='module')
def tiny(tmp_path_factory):
    """The tiny case generated once on a process pool (2 workers)."""
    tmp = tmp_path_factory.mktemp('cases')
    lib = _library(tmp, {'tiny': TINY})
    case = lib.get('tiny')
    res = generate_case(case, coarse=True, workers=2, train_params=PARAMS, progress=False)
    return lib, case, res


def test_shipped_cases_are_valid_and_varied():
    lib = library()
    names = lib.names()
    assert names[0] == 'default' and len(names) >= 9
    cases = lib.cases()
    scenes = [c.scene for c in cases]
    assert all(c.description for c in cases)
    n_lesions = [len(s.tumours) for s in scenes]
    assert 0 in n_lesions and max(n_lesions) >= 2
    kinds = {t.kind for s in scenes for t in s.tumours}
    assert {'malignant', 'benign'} <= kinds
    assert len({s.radii for s in scenes}) >= 2
    assert len({s.material.youngs for s in scenes}) >= 2
    assert any(t.radius <= 0.005 + 1e-12 for s in scenes for t in s.tumours)  # a small lesion
    for c in cases:  # every case's mesh is named by its breast size, in mm
        assert c.mesh_path.suffix == '.stl'


def test_bad_case_name_names_it():
    with pytest.raises(CaseError, match="unknown case 'no_such_case'.*known cases: default"):
        library().get('no_such_case')
    with pytest.raises(CaseError, match='expected lower-case'):
        library().get('../etc/passwd')


def test_missing_files_name_case_and_field(tmp_path):
    lib = _library(tmp_path, {'tiny': TINY})
    case = lib.get('tiny')
    with pytest.raises(CaseError, match=r"case 'tiny': missing model_path .*mesh_path"):
        case.require()
    with pytest.raises(CaseError, match='no case has a model'):
        lib.random(0)


def test_a_scene_edited_after_its_case_was_made_is_not_ready(tmp_path):
    """A lesion moved in a graded case's scene file: its model would render the lump where it
    was while the exam scores it where it is now, and its FE grade is the old scene's. The
    case is refused with one line, left out of the draw, and shows as changed in `cases list`."""
    from haptic_anfis.tissue.dataset import DATA_DIR
    name = 'lib_m_dense_idc20_d12'
    text = (SCENE_DIR / f'{name}.yaml').read_text()
    sd = tmp_path / 'scenes'
    sd.mkdir()
    (sd / f'{name}.yaml').write_text(text)
    lib = CaseLibrary(sd, DATA_DIR, work_root=tmp_path / 'work')
    assert lib.get(name).require() and lib.get(name).level is not None   # as generated
    assert [c.name for c in lib.ready()] == [name]
    assert '[-15, 12]' in text
    (sd / f'{name}.yaml').write_text(text.replace('[-15, 12]', '[20, -15]'))
    case = lib.get(name)
    with pytest.raises(CaseError, match=f"case '{name}': its scene file .* changed since its "
                                        'model was made') as e:
        case.require()
    assert f'cases generate {name}' in str(e.value) and '\n' not in str(e.value)
    assert case.level is None and lib.ready() == []
    with pytest.raises(CaseError, match='no case has a model|no case is ready'):
        lib.random(0)
    row = case_summary(case, timing=False, contrast=False)
    assert 'changed since' in row['scene_changed']
    # a label the FE does not see (the description) changes nothing
    (sd / f'{name}.yaml').write_text(text.replace('description:', 'description: edited,', 1))
    assert lib.get(name).scene_changed() is None


def test_train_only_without_a_dataset_runs_no_fe(tmp_path, capsys, monkeypatch):
    """`cases generate --train-only` promises no FE: a case without its dataset is one line,
    not an hours-long sweep."""
    from haptic_anfis.cases import generate
    from haptic_anfis.cli import main
    _library(tmp_path, {'tiny': TINY})

    def no_sweep(*a, **k):
        raise AssertionError('an FE sweep started under --train-only')
    monkeypatch.setattr(generate, 'sweep_case', no_sweep)
    assert main(['cases', 'generate', 'tiny', '--train-only', '--scene-dir',
                 str(tmp_path / 'scenes'), '--data-dir', str(tmp_path / 'data'), '--work-root',
                 str(tmp_path / 'work')]) == 1
    err = capsys.readouterr().err
    assert "case 'tiny': no dataset" in err and '--train-only runs no FE' in err


def test_lesion_outside_the_breast_names_case_and_field(tmp_path):
    bad = json.loads(json.dumps(TINY))
    bad['tumours'][0]['depth_mm'] = 44  # centre 1 mm above the chest wall: sphere pokes through
    lib = _library(tmp_path, {'tiny': bad})
    with pytest.raises(CaseError, match=r"case 'tiny'.*tumours\[0\].*not inside the tissue"):
        _ = lib.get('tiny').scene


@pytest.mark.parametrize('edit, message', [
    (lambda t: t['tumours'][0].update(radius_mm=2), r'radius_mm: expected 2.5 to 12.5 mm'),
    (lambda t: t['tumours'][0].update(radius_mm=13), r'radius_mm: expected 2.5 to 12.5 mm'),
    (lambda t: t['loading'].update(ring_diameters=[1.0, 0.5]), r'ring_diameters: expected'),
    (lambda t: t['loading'].update(ring_diameters=[1.0], ring_points=0), r'ring_points'),
    (lambda t: t['tumours'][0].update(kind='cyst'), r'kind: expected one of'),
    (lambda t: t['tumours'][0].update(centre_mm=[30, 15, 0]), r'either centre_mm'),
    (lambda t: t['tumours'][0].update(position_mm=[90, 0]), r'not inside the tissue'),
    (lambda t: t['tumours'].extend([dict(t['tumours'][0], position_mm=[-15, 0])] * 3),
     r'at most 3 lesions'),
    (lambda t: t['tumours'].append(dict(t['tumours'][0], position_mm=[20, 0])), r'overlaps'),
    (lambda t: t['tumours'].append(dict(t['tumours'][0], position_mm=[-15, 0])),
     r"tumours\[1\]\.name: 'idc' is also the name of tumours\[0\]"),
    (lambda t: t['loading'].update(refine_spacing_mm=20), r'finer than spacing'),
    (lambda t: t['loading'].pop('refine_margin_mm'), r'both > 0'),
    (lambda t: t.update(description='two\nlines'), r'one line'),
])
def test_invalid_lesions_raise_clear_errors(edit, message):
    doc = json.loads(json.dumps(TINY))
    edit(doc)
    with pytest.raises(SceneError, match=message):
        parse_scene(doc)


def test_refinement_adds_points_near_lesions_and_the_mirror_point():
    s = parse_scene(TINY)
    base = parse_scene({**TINY, 'loading': {k: v for k, v in TINY['loading'].items()
                                            if not k.startswith('refine')}})
    p, p0 = loading_points(s), loading_points(base)
    np.testing.assert_array_equal(p[:len(p0)], p0)  # base ids unchanged
    extra = p[len(p0):, 1:]
    t = s.tumours[0]
    d = np.hypot(extra[:, 0] - t.centre[1], extra[:, 1] - t.centre[2])
    mirror = np.hypot(extra[:, 0] + t.centre[1], extra[:, 1] + t.centre[2]) < 1e-9
    assert len(extra) > 0 and np.all((d <= t.radius + 1e-3 + 1e-9) | mirror)
    over = np.hypot(p[:, 1] - t.centre[1], p[:, 2] - t.centre[2]) < 1e-9
    assert over.sum() == 1  # a point exactly over the lesion centre (here also a base point)
    # the default scene's points (and hash) are untouched by the format's additions
    assert len(loading_points(load_scene(SCENE_DIR / 'default.yaml'))) == 149


def test_generate_train_load_predict(tiny):
    lib, case, res = tiny
    assert not res.failed and res.samples == 3 * len(loading_points(case.scene))
    assert case.require() is case  # dataset, model and mesh exist now
    ds = load_dataset(case.dataset_path)
    assert ds.provenance['case'] == 'tiny' and ds.provenance['coarse'] is True
    import trimesh

    mesh = trimesh.load(case.mesh_path)
    assert mesh.bounds[1] == pytest.approx([45.0, 70.0, 70.0], rel=2e-3)  # millimetres
    from haptic_anfis.anfis import ForceModel

    model = ForceModel.load(case.model_path)
    assert model.metadata_['case']['name'] == 'tiny'
    F = model.predict(ds.X)
    assert np.all(np.isfinite(F)) and np.corrcoef(F[:, 0], ds.Y[:, 0])[0, 1] > 0.95
    row = case_summary(case, timing=False)
    assert row['dataset_rows'] == len(ds) and row['rules'] == 3 * 8  # 2-2-2 over (y, z, depth)
    assert len(row['rmse_n']) == 3 and len(row['rmse_pct_range']) == 3
    assert row['lesions'][0]['kind'] == 'malignant'
    assert row['lesions'][0]['depth_mm'] == pytest.approx(14.0)
    con = lesion_contrast(case, model, ds)
    assert con[0]['fe_contrast'] is not None and con[0]['fe_contrast'] > 0  # stiffer over it
    assert lib.random(3).name == 'tiny'


def test_generate_is_deterministic_and_resumes(tiny, tmp_path):
    lib, case, _ = tiny
    # Re-running reads the finished points from the work dir (no FE) and trains to the same model.
    before = case.model_path.read_text()
    before_data = case.dataset_path.read_bytes()
    res = generate_case(case, coarse=True, workers=1, train_params=PARAMS, progress=False)
    assert res.fe_elapsed_s < 5.0  # nothing to solve: every point was on disk
    assert case.dataset_path.read_bytes() == before_data

    def numbers(text):
        d = json.loads(text)
        return [o['mfs'] if 'mfs' in o else o for o in d['outputs']]
    assert numbers(case.model_path.read_text()) == numbers(before)


def test_generate_on_a_dask_local_cluster(tiny, tmp_path):
    distributed = pytest.importorskip('distributed')
    _, case, _ = tiny
    ref = load_dataset(case.dataset_path)
    lib = _library(tmp_path, {'tiny': TINY})
    other = lib.get('tiny')
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        res = generate_case(other, coarse=True, executor=client.get_executor(), train=False,
                            progress=False)
    assert not res.failed
    ds = load_dataset(other.dataset_path)
    np.testing.assert_array_equal(ds.X, ref.X)
    np.testing.assert_allclose(ds.Y, ref.Y, rtol=1e-9, atol=1e-12)  # same FE, other executor


def test_cli_list_json_and_errors(tiny, capsys, monkeypatch):
    from haptic_anfis.cli import main

    assert main(['cases', 'list', '--json', '--no-timing']) == 0
    rows = json.loads(capsys.readouterr().out)
    names = [r['name'] for r in rows]
    assert names[0] == 'default'
    need = {'name', 'lesions', 'rules', 'rmse_n', 'rmse_pct_range', 'dataset_rows', 'dataset_path',
            'model_path', 'mesh_path'}
    assert all(need <= set(r) for r in rows)
    d = rows[0]
    assert d['lesions'][0]['kind'] == 'malignant' and d['rules'] > 0 and len(d['rmse_n']) == 3
    assert set(d['lesions'][0]) >= {'center_mm', 'radius_mm', 'modulus_kpa', 'kind'}
    assert main(['cases', 'generate', 'no_such_case']) == 1
    assert "unknown case 'no_such_case'" in capsys.readouterr().err


def test_lesion_case_reuses_the_lesion_free_solves_away_from_its_lesions(tmp_path):
    from haptic_anfis.cases.generate import REUSE_MARGIN, base_case, reuse_plan

    base_doc = {**json.loads(json.dumps(TINY)), 'name': 'base', 'tumours': []}
    soft = json.loads(json.dumps(TINY))
    soft['material']['youngs_kPa'] = 19  # a fatty breast: forces scale by 19 / 33 away from it
    lib = _library(tmp_path, {'base': base_doc, 'soft': soft})
    cases = lib.cases()
    base, case = lib.get('base'), lib.get('soft')
    assert base_case(case, cases).name == 'base' and base_case(base, cases) is None
    plan, scale = reuse_plan(case, base)
    assert scale == pytest.approx(19 / 33) and 0 < len(plan) < len(loading_points(case.scene))
    t = case.scene.tumours[0]
    pts = loading_points(case.scene)
    for i in plan:  # only points well away from the lesion are reused
        assert np.hypot(pts[i, 1] - t.centre[1], pts[i, 2] - t.centre[2]) > t.radius + REUSE_MARGIN
    generate_case(base, coarse=True, train=False, progress=False, workers=2)
    res = generate_case(case, coarse=True, train=False, progress=False, workers=2, cases=cases)
    assert not res.failed
    ds, bds = load_dataset(case.dataset_path), load_dataset(base.dataset_path)
    assert sorted(ds.provenance['reused']['points']) == sorted(plan)
    assert len(ds) == 3 * len(pts)
    for i, j in plan.items():
        np.testing.assert_allclose(ds.Y[ds.point == i], bds.Y[bds.point == j] * scale, rtol=1e-12)
    solved = [i for i in range(len(pts)) if i not in plan]
    assert sorted(ds.provenance['reused']['solved_points']) == solved
    # and the solved points see the softer tissue and the lesion: the lesion point is stiffer
    # than the base there times the modulus ratio
    over = int(np.argmin(np.hypot(pts[:, 1] - t.centre[1], pts[:, 2] - t.centre[2])))
    assert np.all(ds.Y[ds.point == over, 0] > scale * bds.Y[bds.point == over, 0])


def test_a_case_with_a_failed_fe_point_is_not_ready_and_says_generate_cannot_help(tmp_path,
                                                                                    monkeypatch):
    """A graded case whose store holds a point that failed in every attempt: `sim --case` must
    not send the user to `cases generate` (the builder refuses a case with a hole); the line
    names the point, the attempts, the depth reached, and points to the ready cases. The
    builder's refusal carries the same one-line summary."""
    import importlib
    from haptic_anfis.cases.sweeps import case_stores, stored_records
    from haptic_anfis.tissue.store import PointStore, failure_summary, store_manifest

    name = 'benign_fibrous'
    sd = tmp_path / 'scenes'
    sd.mkdir()
    (sd / f'{name}.yaml').write_text((SCENE_DIR / f'{name}.yaml').read_text())
    lib = CaseLibrary(sd, tmp_path / 'data', work_root=tmp_path / 'work')
    case = lib.get(name)
    root = tmp_path / 'store'
    monkeypatch.setattr(importlib.import_module('haptic_anfis.cases.library'),
                        'default_store_root', lambda: root)
    with pytest.raises(CaseError, match='make it with `haptic-anfis cases generate'):
        case.require()  # nothing solved, nothing failed: generating it is the way
    error = ('attempt 1 (step 4 mm): stopped at 12 mm: no convergence from depth 12.121 mm '
             'towards 12.121 mm after 6 cut-backs: Maximum number of iterations reached.\n; '
             'attempt 2 (step 2 mm): stopped at 10 mm: no convergence from depth 10.5 mm '
             'towards 10.5 mm after 8 cut-backs: Maximum number of iterations reached.\n')
    store = PointStore(root / name, store_manifest(case.scene, case.scene.mesh.probe_cells))
    store.save_failure('y-018000_z-018000', {'status': 'failed', 'error': error, 'attempts': 2})
    assert failure_summary(error) == ('2 attempt(s) failed, the last (load step 2 mm) stopped at '
                                      '10 mm: no convergence from depth 10.5 mm towards 10.5 mm '
                                      'after 8 cut-backs')
    with pytest.raises(CaseError) as e:
        case.require()
    msg = str(e.value)
    assert '\n' not in msg and f"case '{name}' is not ready" in msg
    assert 'y-018000_z-018000 did not solve (2 attempt(s) failed' in msg
    assert f'`haptic-anfis cases generate {name}` refuses it too' in msg
    assert 'cases list' in msg
    with pytest.raises(CaseError, match=r'y-018000_z-018000 did not solve \(2 attempt\(s\) '
                                        r'failed.*refusing to ship a case with a hole') as e:
        stored_records(case_stores(case, root))
    assert '\n' not in str(e.value)
