"""Grading against the background: a lesion's bump against the normal nodules' bumps."""
import dataclasses

import numpy as np
import pytest

from haptic_anfis.cases.background import background_grades, summary_fields, trend_fit
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.scene import SCENE_DIR, load_scene

DEPTHS = (0.002, 0.005, 0.008, 0.012, 0.016)
#: the threshold these synthetic maps are built around [%] (given, not the config's default)
THR = 7.0


def _records(scene, bumps):
    """Point records of a synthetic force map: a smooth dome trend (more force where the breast
    is thinner) times (1 + the sum of Gaussian bumps of 8 mm width at each (y, z, fraction))."""
    out = []
    for p in loading_points(scene):
        y, z = p[1], p[2]
        base = 6.0 + 40.0 * (y * y + z * z) + 3.0 * y
        g = sum(a * np.exp(-((y - cy) ** 2 + (z - cz) ** 2) / (2 * 0.004 ** 2))
                for cy, cz, a in bumps)
        f = base * (1.0 + g)
        out.append({'surface_point_m': p.tolist(), 'depths_m': list(DEPTHS),
                    'forces_N': [[f * d / 0.008, 0.0, 0.0] for d in DEPTHS]})
    return out


@pytest.fixture(scope='module')
def scene():
    return load_scene(SCENE_DIR / 'nod_s_fatty_idc10_d10.yaml')


def test_the_trend_follows_a_smooth_map_and_ignores_one_bump():
    rng = np.random.default_rng(3)
    yz = rng.uniform(-0.03, 0.03, size=(200, 2))
    smooth = 5.0 + 30.0 * yz[:, 0] ** 2 + 20 * yz[:, 1]
    f = smooth.copy()
    f[7] *= 1.3
    t = trend_fit(yz, f)
    np.testing.assert_allclose(np.delete(t, 7), np.delete(smooth, 7), rtol=2e-3)


def test_a_lesion_that_bulges_far_above_the_nodules_stands_out_easily(scene):
    nod = [(n.centre[1], n.centre[2], 0.03) for n in scene.background.nodules]
    t = scene.tumours[0]
    g = background_grades(scene, _records(scene, nod + [(t.centre[1], t.centre[2], 0.6)]),
                          threshold_pct=THR)
    assert g['background'] == 'nodular' and len(g['nodules']) == 30
    lo, hi = g['nodule_bump_pct']
    assert -2.0 < lo <= hi < 7.0  # 3 % bumps (less the trend they lift): under the 7 % threshold
    assert g['confounders'] == []
    (les,) = g['lesions']
    assert les['bump_pct'] > 40 and les['stands_out'] and les['difficulty'] == 1
    assert g['level'] == 1


def test_a_lesion_no_larger_than_the_nodules_does_not_stand_out(scene):
    nod = [(n.centre[1], n.centre[2], 0.16) for n in scene.background.nodules]
    t = scene.tumours[0]
    g = background_grades(scene, _records(scene, nod + [(t.centre[1], t.centre[2], 0.16)]),
                          threshold_pct=THR)
    (les,) = g['lesions']
    assert les['bump_pct'] > 7.0  # palpable on a smooth breast ...
    assert not les['stands_out'] and les['difficulty'] == 5 and g['level'] == 5  # ... not here
    assert len(g['confounders']) >= 10  # 16 % nodules are felt: each a possible false mark


def test_a_lesion_free_nodular_case_is_level_2_when_its_nodules_are_felt(scene):
    free = dataclasses.replace(scene, tumours=(), ring_diameters=(), ring_points=0)
    soft = [(n.centre[1], n.centre[2], 0.02) for n in free.background.nodules]
    assert background_grades(free, _records(free, soft), threshold_pct=THR)['level'] == 1
    firm = [(n.centre[1], n.centre[2], 0.12) for n in free.background.nodules]
    assert background_grades(free, _records(free, firm), threshold_pct=THR)['level'] == 2


def test_cases_list_fields_name_the_background_and_the_ribs(scene):
    ribs = load_scene(SCENE_DIR / 'nod_s_fatty_ribs_free.yaml')
    assert summary_fields(scene, None) == {'background': 'nodular 30', 'nodules': 30,
                                           'nodule_bump_pct': None, 'ribs': 0}
    f = summary_fields(ribs, {'nodule_bump_pct': [0.5, 4.25]})
    assert f['background'] == 'nodular 30 (+0.5..+4.2 %)' and f['ribs'] == 4
    smooth = load_scene(SCENE_DIR / 'lib_s_fatty_two.yaml')
    assert summary_fields(smooth, None)['background'] == 'smooth'


#: a tiny nodular case: coarse mesh, 3 depths, 9 base points, one lesion with a ring of 4, two
#: explicit glandular nodules and one rib under the breast (+ 1 twin point)
TINY_NODULAR = {
    'name': 'tinynodular', 'description': 'test case: one lesion among two nodules over a rib',
    'breast': {'radii_mm': [45, 70, 70]},
    'material': {'youngs_kPa': 19, 'poisson': 0.499},
    'tumours': [{'name': 'idc', 'kind': 'malignant', 'position_mm': [12, 6], 'depth_mm': 9,
                 'radius_mm': 6, 'youngs_kPa': 93}],
    'background': {
        'nodules': {'youngs_kPa': 33, 'source': 'test',
                    'items': [{'position_mm': [-20, 0], 'depth_mm': 8, 'radius_mm': 4},
                              {'position_mm': [0, -20], 'depth_mm': 8, 'radius_mm': 4}]},
        'ribs': {'z_mm': [20], 'width_mm': 12, 'height_mm': 9, 'cover_mm': 5,
                 'youngs_kPa': 2000, 'source': 'test'}},
    'probe': {'diameter_mm': 16},
    'loading': {'spacing_mm': 20, 'palpable_radius_mm': 30, 'ring_diameters': [1.0],
                'ring_points': 4, 'depths_mm': [2, 5, 8], 'max_step_mm': 4},
    'mesh': {'probe_cells': 4, 'coarse_probe_cells': 2, 'edge_offset': 0.2, 'edge_refine': 0},
}


def test_a_nodular_case_is_swept_graded_against_its_background_and_listed(tmp_path, monkeypatch):
    from test_cases import _library  # the same throw-away library of scene files

    from haptic_anfis.cases import build as build_mod
    from haptic_anfis.cases.build import build_case
    from haptic_anfis.cases.summary import case_summary
    from haptic_anfis.cases.sweeps import sweep_case_store

    lib = _library(tmp_path, {'tinynodular': TINY_NODULAR})
    case = lib.get('tinynodular')
    st = sweep_case_store(case, root=tmp_path / 'store', coarse=True, workers=1, progress=False)
    assert st.complete
    monkeypatch.setattr(build_mod, 'RANGE_GATE_PCT', 1e9)   # the tiny model is not the point here
    monkeypatch.setattr(build_mod, 'CONTRAST_GATE', 1e9)
    monkeypatch.setattr('haptic_anfis.cases.background.FEATURE_GATE', 1e9)
    res = build_case(case, store_root=tmp_path / 'store', coarse=True,
                     train_params={'structure': (2, 2, 2), 'epochs': 8, 'search_folds': 1,
                                   'seed': 0}, folds=3, seeds=(0,))
    bg = case.grading()['background']
    assert bg['background'] == 'nodular' and len(bg['nodules']) == 2 and len(bg['ribs']) == 1
    (les,) = bg['lesions']
    assert les['lesion'] == 'idc' and res.level == bg['level'] == les['difficulty']
    assert les['stands_out'] == (les['margin_pct'] >= bg['threshold_pct'])
    row = case_summary(case, timing=False, contrast=False)
    lo, hi = bg['nodule_bump_pct']
    assert row['background'] == f'nodular 2 ({lo:+.1f}..{hi:+.1f} %)' and row['ribs'] == 1
    assert row['fe_points']['total'] == 16  # the full-density store: swept per point too
