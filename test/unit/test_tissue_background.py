"""A scene's normal background: seeded nodules, ribs, their validation, their moduli in the FE."""
import copy

import numpy as np
import pytest
import yaml

from haptic_anfis.tissue.fe import scene_mesh, scene_moduli
from haptic_anfis.tissue.scene import SCENE_DIR, SceneError, load_scene, parse_scene

NODULAR = SCENE_DIR / 'nod_s_fatty_idc6_d12_ribs.yaml'


@pytest.fixture(scope='module')
def raw():
    return yaml.safe_load(NODULAR.read_text())


def _with(raw, **background):
    d = copy.deepcopy(raw)
    for key, value in background.items():
        if value is None:
            d['background'].pop(key)
        else:
            d['background'][key] = value
    return d


def _items(raw, *items):
    nod = {k: v for k, v in raw['background']['nodules'].items()
           if k not in ('seed', 'count', 'radius_mm', 'depth_mm', 'extent_mm', 'min_gap_mm')}
    return {**nod, 'items': list(items)}


def test_a_nodular_scene_draws_the_same_nodules_from_its_seed_every_time(raw):
    a, b = parse_scene(copy.deepcopy(raw)), load_scene(NODULAR)
    assert a.background.nodules == b.background.nodules
    assert a.background.kind == 'nodular'
    assert len(a.background.nodules) == raw['background']['nodules']['count']
    assert len(a.background.ribs) == 4
    assert all(n.kind == 'glandular' for n in a.background.nodules)  # stiffer than the fat
    other = _with(raw, nodules={**raw['background']['nodules'], 'seed': 99})
    assert parse_scene(other).background.nodules != a.background.nodules
    assert parse_scene(other).fe_sha256() != a.fe_sha256()  # the store knows its nodules


def test_drawn_nodules_keep_apart_from_each_other_the_lesion_and_the_ribs(raw):
    s = parse_scene(copy.deepcopy(raw))
    nod = s.background.nodules
    c = np.array([n.centre for n in nod])
    r = np.array([n.radius for n in nod])
    d = np.linalg.norm(c[:, None] - c[None], axis=2) - r[:, None] - r[None]
    np.fill_diagonal(d, np.inf)
    assert d.min() >= 1e-3 - 1e-12  # min_gap_mm: 1
    t = s.tumours[0]
    assert (np.linalg.norm(c - t.centre, axis=1) - r - t.radius).min() >= 1e-3 - 1e-12
    for rib in s.background.ribs:
        gap = np.hypot(c[:, 0] - rib.axis_x, c[:, 2] - rib.z) - r - rib.radius
        assert gap.min() >= 1e-3 - 1e-12


def test_a_scene_without_background_keeps_its_hash():
    s = load_scene(SCENE_DIR / 'lib_s_fatty_two.yaml')
    assert s.background is None
    assert s.sha256().startswith('c140403be0')  # the hash in its committed store and model


@pytest.mark.parametrize('change, message', [
    (lambda raw: _with(raw, nodules=_items(raw, {'position_mm': [0, 0], 'depth_mm': 1,
                                                 'radius_mm': 3})),
     r'background\.nodules\[0\] \(nodule0\): nodule .* is outside the breast'),
    (lambda raw: _with(raw, nodules=_items(raw, {'centre_mm': [10, 70, 0], 'radius_mm': 3})),
     r'background\.nodules\[0\] \(nodule0\): nodule .* is outside the breast'),
    (lambda raw: _with(raw, nodules=_items(raw, {'position_mm': [12, 8], 'depth_mm': 12,
                                                 'radius_mm': 3})),
     r'background\.nodules\[0\] \(nodule0\): overlaps tumours\[0\] \(idc1\)'),
    (lambda raw: _with(raw, nodules=_items(raw, {'position_mm': [-20, -20], 'depth_mm': 10,
                                                 'radius_mm': 3},
                                           {'position_mm': [-18, -20], 'depth_mm': 10,
                                            'radius_mm': 3, 'name': 'second'})),
     r'background\.nodules\[1\] \(second\): overlaps background\.nodules\[0\] \(nodule0\)'),
    (lambda raw: _with(raw, nodules=_items(raw, {'centre_mm': [5, 0, 15], 'radius_mm': 2})),
     r'background\.nodules\[0\] \(nodule0\): overlaps ribs\[2\] \(z = 15 mm\)'),
    (lambda raw: _with(raw, ribs={**raw['background']['ribs'], 'width_mm': 24, 'height_mm': 22,
                                 'z_mm': [-15, 15]}),
     r'background\.ribs\[\d\] \(z = -?\d+ mm\): a rib through the skin'),
    (lambda raw: _with(raw, ribs={**raw['background']['ribs'], 'z_mm': [0, 5]}),
     r'background\.ribs\[1\] \(z = 5 mm\): overlaps ribs\[0\]'),
    (lambda raw: _with(raw, ribs={**raw['background']['ribs'], 'z_mm': [58]}),
     r'background\.ribs\[0\] \(z = 58 mm\): lies outside the breast'),
    (lambda raw: _with(raw, nodules={**raw['background']['nodules'], 'count': 400,
                                     'extent_mm': 10}),
     r'background\.nodules: placed only \d+ of count 400'),
    (lambda raw: _with(raw, nodules={**raw['background']['nodules'], 'youngs_kPa': 19}),
     r"background\.nodules\.youngs_kPa: 19 kPa is the breast's own modulus"),
    (lambda raw: _with(raw, nodules={**raw['background']['nodules'], 'source': ''}),
     r'background\.nodules\.source'),
    (lambda raw: _with(raw, nodules={**raw['background']['nodules'], 'radius_mm': [2, 12]}),
     r'background\.nodules\.radius_mm: expected within'),
    (lambda raw: _with(raw, lumps=1), r"background: unknown key\(s\) \['lumps'\]"),
])
def test_bad_backgrounds_are_refused_in_one_line_naming_the_region(raw, change, message):
    with pytest.raises(SceneError, match=message) as e:
        parse_scene(change(raw))
    assert '\n' not in str(e.value)


def test_a_rib_that_reaches_the_lesion_is_refused(raw):
    d = copy.deepcopy(raw)
    d['tumours'][0]['position_mm'] = [12, 15]
    d['tumours'][0]['depth_mm'] = 24  # centre about 9 mm above the chest wall, over ribs[2]
    with pytest.raises(SceneError, match=r'background\.ribs\[2\] \(z = 15 mm\): overlaps '
                                         r'tumours\[0\] \(idc1\)'):
        parse_scene(d)


def test_the_fe_gives_nodules_and_ribs_their_moduli_cell_by_cell():
    s = load_scene(NODULAR)
    mesh = scene_mesh(s, (0.0, 0.0), s.mesh.coarse_probe_cells)
    mu, bulk = scene_moduli(s, mesh)
    nu = s.material.poisson
    fat, gland = s.material.shear, 33e3 / (2 * (1 + nu))
    rib = s.background.ribs[0].youngs / (2 * (1 + nu))
    assert mu.min() == pytest.approx(fat) and 0.8 * rib < mu.max() <= rib * (1 + 1e-12)
    mid = mesh.points[mesh.cells].mean(axis=1)
    n = s.background.nodules[0]
    inside = np.linalg.norm(mid - n.centre, axis=1) < 0.3 * n.radius
    if inside.any():  # a cell well inside the nodule carries (about) the glandular modulus
        assert mu[inside].max() == pytest.approx(gland, rel=0.05)
    # cells whose centre lies deep in a rib's section are about bone-stiff; cells far from every
    # region keep the fat's modulus
    ribs = s.background.ribs
    d_rib = np.min([np.hypot(mid[:, 0] - r.axis_x, mid[:, 2] - r.z) / r.radius for r in ribs],
                   axis=0)
    core = (d_rib < 0.6) & (mid[:, 0] < ribs[0].top - 2e-3)
    assert core.sum() >= 5 and np.median(mu[core]) > 0.5 * rib
    d_nod = np.min([np.linalg.norm(mid - n.centre, axis=1) - n.radius
                    for n in (*s.background.nodules, *s.tumours)], axis=0)
    free = (d_rib > 2.0) & (d_nod > 0.01) & (np.hypot(mid[:, 1], mid[:, 2]) < 0.03)
    assert free.sum() > 20 and np.all(mu[free] == pytest.approx(fat))
    np.testing.assert_allclose(bulk / mu, s.material.bulk_ratio())


def test_a_lesion_free_nodular_scene_is_graded_and_swept_per_point():
    free = load_scene(SCENE_DIR / 'nod_s_fatty_free.yaml')
    assert not free.ring_diameters and free.background is not None and free.graded
    assert load_scene(SCENE_DIR / 'lib_free_s_fatty.yaml').graded  # rings, no background
    assert not load_scene(SCENE_DIR / 'normal.yaml').background
