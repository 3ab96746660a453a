"""Grading against the background: a lesion's bump against the normal nodules' bumps."""
import dataclasses

import numpy as np
import pytest

from haptic_anfis.cases.background import background_grades, summary_fields, trend_fit
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.scene import SCENE_DIR, load_scene

DEPTHS = (0.002, 0.005, 0.008, 0.012, 0.016)


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
    g = background_grades(scene, _records(scene, nod + [(t.centre[1], t.centre[2], 0.6)]))
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
    g = background_grades(scene, _records(scene, nod + [(t.centre[1], t.centre[2], 0.16)]))
    (les,) = g['lesions']
    assert les['bump_pct'] > 7.0  # palpable on a smooth breast ...
    assert not les['stands_out'] and les['difficulty'] == 5 and g['level'] == 5  # ... not here
    assert len(g['confounders']) >= 10  # 16 % nodules are felt: each a possible false mark


def test_a_lesion_free_nodular_case_is_level_2_when_its_nodules_are_felt(scene):
    free = dataclasses.replace(scene, tumours=(), ring_diameters=(), ring_points=0)
    soft = [(n.centre[1], n.centre[2], 0.02) for n in free.background.nodules]
    assert background_grades(free, _records(free, soft))['level'] == 1
    firm = [(n.centre[1], n.centre[2], 0.12) for n in free.background.nodules]
    assert background_grades(free, _records(free, firm))['level'] == 2


def test_cases_list_fields_name_the_background_and_the_ribs(scene):
    ribs = load_scene(SCENE_DIR / 'nod_s_fatty_ribs_free.yaml')
    assert summary_fields(scene, None) == {'background': 'nodular 30', 'nodules': 30,
                                           'nodule_bump_pct': None, 'ribs': 0}
    f = summary_fields(ribs, {'nodule_bump_pct': [0.5, 4.25]})
    assert f['background'] == 'nodular 30 (+0.5..+4.2 %)' and f['ribs'] == 4
    smooth = load_scene(SCENE_DIR / 'lib_s_fatty_two.yaml')
    assert summary_fields(smooth, None)['background'] == 'smooth'
