"""Grading against the background: a lesion's contrast over the smooth breast against the normal
nodules' contrasts, per depth."""
import dataclasses

import numpy as np
import pytest

from haptic_anfis.cases.background import (background_grades, regrade_background, separation_pct,
                                           summary_fields)
from haptic_anfis.cases.grading import PALPABLE_PCT
from haptic_anfis.cases.reference import SmoothReference
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.scene import SCENE_DIR, load_scene

DEPTHS = (0.002, 0.005, 0.008, 0.012, 0.016)
#: [m] width (sigma) of a synthetic bump: about a 16 mm probe's reach over a small region
SIGMA = 0.004


def _base(y, z, depth: float):
    """|F| [N] of a smooth synthetic breast: more force where it is thinner, and a tilt; curved
    enough that a trend fitted to the map would bend under a 30 mm bump."""
    return (6.0 + 40.0 * (y * y + z * z) + 3.0 * y) * depth / 0.008


class _Smooth:
    """The synthetic smooth breast as a reference (what :class:`SmoothReference` provides)."""
    name = 'synthetic'

    def forces(self, yz, depth):
        return _base(yz[:, 0], yz[:, 1], depth)


def _records(scene, bumps):
    """Point records of the smooth map times (1 + the sum of Gaussian bumps): ``bumps`` are
    (y, z, amplitude) with the amplitude a fraction or a {depth: fraction} dict."""
    out = []
    for p in loading_points(scene):
        y, z = p[1], p[2]
        forces = []
        for d in DEPTHS:
            g = sum((a[d] if isinstance(a, dict) else a)
                    * np.exp(-((y - cy) ** 2 + (z - cz) ** 2) / (2 * SIGMA ** 2))
                    for cy, cz, a in bumps)
            forces.append([_base(y, z, d) * (1.0 + g), 0.0, 0.0])
        out.append({'surface_point_m': p.tolist(), 'depths_m': list(DEPTHS), 'forces_N': forces})
    return out


@pytest.fixture(scope='module')
def scene():
    return load_scene(SCENE_DIR / 'nod_s_fatty_idc10_d10.yaml')


#: [m] (y, z, radius) of three nodules on the 4 mm grid, over 20 mm from the scene's lesion at
#: (-10, -14) mm and from each other: their bumps (SIGMA 4 mm) do not add up
SPARSE = ((0.016, 0.016, 0.003), (-0.016, 0.016, 0.003), (0.016, -0.012, 0.003))


def _with_nodules(scene, nodules):
    """``scene`` with its nodules replaced by glandular ones at (y, z, radius) [m], 10 mm deep."""
    tpl = scene.background.nodules[0]
    nod = tuple(dataclasses.replace(tpl, name=f'n{i}', centre=(tpl.centre[0], y, z), radius=r)
                for i, (y, z, r) in enumerate(nodules))
    return dataclasses.replace(scene, background=dataclasses.replace(scene.background,
                                                                     nodules=nod))


def test_the_contrasts_of_known_bumps_are_recovered(scene):
    """A region with a grid point over its centre reads its bump exactly at every depth (no
    trend soaks it up), however curved the smooth breast."""
    sc = _with_nodules(scene, SPARSE)
    t = sc.tumours[0]
    amp = {d: 0.10 + 5.0 * d for d in DEPTHS}   # 11 .. 18 %: the lesion grows with depth
    nod = [(n.centre[1], n.centre[2], 0.05) for n in sc.background.nodules]
    g = background_grades(sc, _records(sc, nod + [(t.centre[1], t.centre[2], amp)]), _Smooth())
    (les,) = g['lesions']
    for r in les['contrasts']:
        assert r['contrast_pct'] == pytest.approx(100 * amp[r['depth_m']], abs=1e-6)
    for e in g['nodules']:
        for r in e['contrasts']:
            assert r['contrast_pct'] == pytest.approx(5.0, abs=1e-6), (e['name'], r)
    assert g['nodule_bump_pct'] == pytest.approx([5.0, 5.0], abs=1e-6)
    assert g['reference'] == 'synthetic' and g['depths_m'] == list(DEPTHS)


#: lesion contrast per depth (fraction) -> the level: 3 % nodules, the 22 % stylus threshold
#: (a lesion told apart needs 1.03 * 1.22 - 1 = 25.7 % over the smooth breast)
LEVELS = [
    ((0.60, 0.60, 0.60, 0.60, 0.60), 1),   # at light pressure, over twice the threshold
    ((0.30, 0.35, 0.40, 0.45, 0.50), 2),   # at light pressure but under twice: medium
    ((0.10, 0.30, 0.35, 0.40, 0.45), 2),   # from medium pressure
    ((0.10, 0.20, 0.30, 0.35, 0.40), 3),   # from deep pressure
    ((0.05, 0.10, 0.20, 0.30, 0.35), 4),   # only deeper than the exam's deep level
    ((0.05, 0.10, 0.15, 0.20, 0.30), 5),   # only at the deepest FE depth
    ((0.05, 0.10, 0.15, 0.20, 0.24), 5),   # felt (>= 22 %) but never told from the nodules
]


@pytest.mark.parametrize('contrast,level', LEVELS)
def test_every_level_1_to_5_is_reached_by_where_the_lesion_is_told_apart(scene, contrast, level):
    sc = _with_nodules(scene, SPARSE)
    t = sc.tumours[0]
    nod = [(n.centre[1], n.centre[2], 0.03) for n in sc.background.nodules]
    amp = dict(zip(DEPTHS, contrast))
    g = background_grades(sc, _records(sc, nod + [(t.centre[1], t.centre[2], amp)]), _Smooth(),
                          threshold_pct=PALPABLE_PCT)
    (les,) = g['lesions']
    assert g['level'] == les['difficulty'] == level
    assert g['confounders'] == []
    found = [d for d, c in zip(DEPTHS, contrast) if separation_pct(100 * c, 3.0) >= 22.0]
    assert les['found_depth_m'] == (found[0] if found else None)
    assert les['stands_out'] == bool(found) and (les['reason'] is None) == bool(found)
    assert les['felt'] == (max(contrast) >= 0.22)


def test_a_grading_regraded_at_another_threshold_is_the_grading_at_that_threshold(scene):
    """A trainee's own threshold: the stored per-depth contrasts graded again give what a fresh
    grading at that threshold gives (a 10 % threshold tells the level-4 lesion apart from deep
    pressure: at 5 mm it is 6.8 % over the 3 % nodules, under it; at 8 mm 16.5 %)."""
    sc = _with_nodules(scene, SPARSE)
    t = sc.tumours[0]
    nod = [(n.centre[1], n.centre[2], 0.03) for n in sc.background.nodules]
    recs = _records(sc, nod + [(t.centre[1], t.centre[2], dict(zip(DEPTHS, LEVELS[4][0])))])
    g22 = background_grades(sc, recs, _Smooth())
    g10 = background_grades(sc, recs, _Smooth(), threshold_pct=10.0)
    assert g22['level'] == 4 and g10['level'] == 3
    again = regrade_background(g22, 10.0)
    assert again['level'] == 3 and again['lesions'] == g10['lesions']
    assert again['normal_by_depth'] == g10['normal_by_depth'] and again['threshold_pct'] == 10.0


def test_a_lesion_no_firmer_than_the_nodules_is_not_told_apart(scene):
    nod = [(n.centre[1], n.centre[2], 0.25) for n in scene.background.nodules]
    t = scene.tumours[0]
    g = background_grades(scene, _records(scene, nod + [(t.centre[1], t.centre[2], 0.30)]),
                          _Smooth())
    (les,) = g['lesions']
    assert les['felt'] and les['bump_pct'] >= 30.0 - 1e-6   # palpable on a smooth breast ...
    assert not les['stands_out'] and les['difficulty'] == 5 == g['level']   # ... not here
    assert 'never told apart' in les['reason']
    assert len(g['confounders']) >= 10   # 25 % nodules are felt: each a possible false mark
    deep = next(n for n in g['normal_by_depth'] if n['depth_m'] == 0.008)
    assert deep['at_threshold'] == len(g['confounders']) and deep['max_pct'] >= 25.0


def test_a_nodule_under_the_lesions_bump_is_not_read_as_a_confounder(scene):
    """A nodule 6.3 mm from a strong lesion, with no bump of its own: the grid point over it
    shows the lesion's flank (17 %); a normal region is read only beyond the lesion's reach (its
    radius plus the probe's), where this one has no point: it is not graded, no confounder, and
    the lesion does not confound itself."""
    t = scene.tumours[0]
    at = (t.centre[1] + 0.006, t.centre[2] + 0.002)   # a 4 mm grid point
    sc = _with_nodules(scene, [(*at, 0.0025), *SPARSE])
    recs = _records(sc, [(t.centre[1], t.centre[2], 0.6)])
    g = background_grades(sc, recs, _Smooth(), threshold_pct=5.0)
    near = g['nodules'][0]
    assert near['bump_pct'] is None and near['contrasts'] == [] and g['confounders'] == []
    assert g['lesions'][0]['difficulty'] == 1 == g['level']
    k = next(i for i, r in enumerate(recs)
             if np.allclose(r['surface_point_m'][1:], at))
    over = recs[k]['forces_N'][2][0] / _base(*at, 0.008) - 1
    assert 100 * over > 15.0   # what the nodule would read at the point over it


def test_a_lesion_free_nodular_case_is_level_2_when_its_nodules_are_felt(scene):
    free = dataclasses.replace(scene, tumours=(), ring_diameters=(), ring_points=0)
    soft = [(n.centre[1], n.centre[2], 0.05) for n in free.background.nodules]
    assert background_grades(free, _records(free, soft), _Smooth())['level'] == 1
    firm = [(n.centre[1], n.centre[2], 0.30) for n in free.background.nodules]
    assert background_grades(free, _records(free, firm), _Smooth())['level'] == 2


def test_bad_threshold_and_missing_depth_are_refused_in_one_line(scene):
    recs = _records(scene, [])
    with pytest.raises(ValueError, match='palpability threshold'):
        background_grades(scene, recs, _Smooth(), threshold_pct=0.0)
    with pytest.raises(ValueError, match='no FE force at the level depth 9 mm'):
        background_grades(scene, recs, _Smooth(), depth=0.009)


def test_the_smooth_reference_interpolates_a_smooth_map_and_scales_with_the_modulus(scene):
    """A smooth map on one grid, read at another grid's points and scaled (neo-Hookean: force
    proportional to the modulus at a fixed geometry)."""
    recs = []
    for y in np.arange(-0.03, 0.0301, 0.0045):
        for z in np.arange(-0.03, 0.0301, 0.0045):
            recs.append({'surface_point_m': [0.0, y, z], 'depths_m': list(DEPTHS),
                         'forces_N': [[_base(y, z, d), 0.0, 0.0] for d in DEPTHS]})
    ref = SmoothReference('grid', 33.0 / 19.0, tuple(recs))
    yz = np.array([p[1:] for p in loading_points(scene)])
    for d in DEPTHS:
        np.testing.assert_allclose(ref.forces(yz, d), 33.0 / 19.0 * _base(yz[:, 0], yz[:, 1], d),
                                   rtol=1e-9)


def test_the_committed_nodular_store_grades_its_lesion_as_its_twin_measures_it():
    """The lesion's contrast over the smooth breast (lib_free_s_fatty's store) against the
    ground truth (the same point without the lesion, the twin store): within 1.5 points at every
    depth (the excess: nodules near the lesion, which the twin keeps and the smooth breast
    lacks)."""
    from haptic_anfis.cases import library
    from haptic_anfis.cases.grading import lesion_grades
    from haptic_anfis.cases.reference import smooth_reference
    from haptic_anfis.cases.sweeps import case_stores, stored_records

    case = library().get('nod_s_fatty_idc10_d10')
    recs, twins = stored_records(case_stores(case))
    g = background_grades(case.scene, recs, smooth_reference(case))
    assert g['reference'] == 'lib_free_s_fatty'
    truth = {r['depth_m']: r['contrast_pct']
             for r in lesion_grades(case.scene, recs, twins)[0]['contrasts']}
    for r in g['lesions'][0]['contrasts']:
        assert 0.0 <= r['contrast_pct'] - truth[r['depth_m']] <= 1.5, r


def test_a_nodular_case_without_a_smooth_breast_of_its_body_is_refused_naming_it(tmp_path):
    from test_cases import _library  # the same throw-away library of scene files

    from haptic_anfis.cases import CaseError
    from haptic_anfis.cases.reference import reference_case

    lib = _library(tmp_path, {'tinynodular': TINY_NODULAR, 'tinyflat': TINY_FLAT})
    with pytest.raises(CaseError, match=r"case 'tinynodular': no smooth lesion-free case .*"
                                        r"breast radii \(45.0, 70.0, 70.0\) mm, .* and 1 ribs"):
        reference_case(lib.get('tinynodular'))
    (tmp_path / 'two').mkdir()
    lib = _library(tmp_path / 'two', {'tinynodular': TINY_NODULAR, 'tinysmooth': TINY_SMOOTH})
    assert reference_case(lib.get('tinynodular')).name == 'tinysmooth'


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
                 'source': 'test'}},
    'probe': {'diameter_mm': 16},
    'loading': {'spacing_mm': 20, 'palpable_radius_mm': 30, 'ring_diameters': [1.0],
                'ring_points': 4, 'depths_mm': [2, 5, 8], 'max_step_mm': 4},
    'mesh': {'probe_cells': 4, 'coarse_probe_cells': 2, 'edge_offset': 0.2, 'edge_refine': 0},
}
#: its smooth breast (the same body over the same rib, no nodule or lesion): the reference its
#: background is graded against
TINY_SMOOTH = {**{k: v for k, v in TINY_NODULAR.items() if k not in ('tumours', 'background')},
               'background': {'ribs': TINY_NODULAR['background']['ribs']},
               'name': 'tinysmooth', 'description': 'test case: the tiny nodular breast, smooth',
               'loading': {**TINY_NODULAR['loading'], 'ring_diameters': [], 'ring_points': 0}}
#: the same breast over a flat chest wall: not the same body as a breast over a rib
TINY_FLAT = {**{k: v for k, v in TINY_SMOOTH.items() if k != 'background'}, 'name': 'tinyflat'}


def test_a_nodular_case_is_swept_graded_against_its_background_and_listed(tmp_path, monkeypatch):
    from test_cases import _library  # the same throw-away library of scene files

    from haptic_anfis.cases import build as build_mod
    from haptic_anfis.cases.build import build_case
    from haptic_anfis.cases.summary import case_summary
    from haptic_anfis.cases.sweeps import sweep_case_store

    lib = _library(tmp_path, {'tinynodular': TINY_NODULAR, 'tinysmooth': TINY_SMOOTH})
    case = lib.get('tinynodular')
    for c in (case, lib.get('tinysmooth')):
        st = sweep_case_store(c, root=tmp_path / 'store', coarse=True, workers=1, progress=False)
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
    assert bg['reference'] == 'tinysmooth'
    assert les['lesion'] == 'idc' and res.level == bg['level'] == les['difficulty']
    assert les['stands_out'] == (les['margin_pct'] >= bg['threshold_pct'])
    row = case_summary(case, timing=False, contrast=False)
    lo, hi = bg['nodule_bump_pct']
    assert row['background'] == f'nodular 2 ({lo:+.1f}..{hi:+.1f} %)' and row['ribs'] == 1
    assert row['fe_points']['total'] == 16  # the full-density store: swept per point too


def test_a_depth_some_points_did_not_reach_is_graded_without_them(scene):
    """A partial point (its load path stopped before 16 mm) is left out at 16 mm only; a depth
    that more than a tenth of the points missed is not graded."""
    sc = _with_nodules(scene, SPARSE)
    t = sc.tumours[0]
    recs = _records(sc, [(t.centre[1], t.centre[2], 0.4)])
    far = [r for r in recs if np.hypot(*np.subtract(r['surface_point_m'][1:], t.centre[1:]))
           > 0.02]
    for r in far[:3]:   # three points at the rim stopped at 12 mm
        r['depths_m'], r['forces_N'] = r['depths_m'][:4], r['forces_N'][:4]
    g = background_grades(sc, recs, _Smooth())
    assert g['depths_m'] == list(DEPTHS)
    (les,) = g['lesions']
    assert [r['contrast_pct'] for r in les['contrasts']] == pytest.approx([40.0] * 5, abs=1e-6)
    for r in far[3:len(recs) // 8]:
        r['depths_m'], r['forces_N'] = r['depths_m'][:4], r['forces_N'][:4]
    assert background_grades(sc, recs, _Smooth())['depths_m'] == list(DEPTHS[:4])


class _RibbedSmooth:
    """A synthetic smooth breast over ribs, flat along z: raised everywhere by 10 %, and by
    ``ridge`` more over each rib (what the ribbed reference provides)."""
    name = 'synthetic ribs'

    def __init__(self, ribs, ridge: float):
        self.ribs, self.ridge = ribs, ridge

    def forces(self, yz, depth):
        over = sum(np.abs(yz[:, 1] - r.z) <= r.radius for r in self.ribs)
        return _base(yz[:, 0], 0.0, depth) * 1.10 * (1.0 + self.ridge * over)


def test_a_rib_reads_its_ridge_over_the_intercostal_tissue_not_the_general_rise():
    sc = load_scene(SCENE_DIR / 'nod_s_fatty_two_ribs.yaml')
    ref = _RibbedSmooth(sc.background.ribs, 0.05)
    recs = []
    for p in loading_points(sc):
        yz = np.array([p[1:]])
        recs.append({'surface_point_m': p.tolist(), 'depths_m': list(sc.depths),
                     'forces_N': [[float(ref.forces(yz, d)[0]), 0.0, 0.0] for d in sc.depths]})
    g = background_grades(sc, recs, ref)
    graded = [r for r in g['ribs'] if r['contrasts']]
    assert [r['name'] for r in graded] == ['rib1', 'rib2']   # the outer two lie beyond the disc
    for r in graded:   # +5 % over the line against halfway to the neighbours (no ridge there)
        assert [c['contrast_pct'] for c in r['contrasts']] == pytest.approx([5.0] * 4, abs=1e-9)
    # the nodules and the lesion read 0 %: the breast's general rise over ribs is no bump
    for e in (*g['nodules'], *g['lesions']):
        assert all(abs(c['contrast_pct']) < 1e-6 for c in e['contrasts']), e['name']
