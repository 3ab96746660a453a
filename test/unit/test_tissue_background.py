"""A scene's normal background: seeded nodules, ribs, their validation, their moduli in the FE."""
import copy

import numpy as np
import pytest
import yaml

from haptic_anfis.tissue.background import Rib, rib_floor
from haptic_anfis.tissue.fe import scene_mesh, scene_moduli
from haptic_anfis.tissue.scene import SCENE_DIR, SceneError, load_scene, parse_scene
from haptic_anfis.tissue.scenebase import surface_height

NODULAR = SCENE_DIR / 'nod_s_fatty_two_ribs.yaml'


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
        t = np.linspace(0.0, np.pi, 721)  # the rib's half-ellipse outline
        d = np.hypot(c[:, :1] - rib.top * np.sin(t), c[:, 2:] - rib.z - rib.radius * np.cos(t))
        gap = d.min(axis=1) - r
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
    (lambda raw: _with(raw, nodules=_items(raw, {'position_mm': [-14, 10], 'depth_mm': 9,
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


def test_the_fe_gives_nodules_their_moduli_cell_by_cell_and_ribs_none():
    s = load_scene(NODULAR)
    mesh = scene_mesh(s, (0.0, 0.0), s.mesh.coarse_probe_cells)
    mu, bulk = scene_moduli(s, mesh)
    nu = s.material.poisson
    fat, fibrous = s.material.shear, s.background.nodules[0].youngs / (2 * (1 + nu))
    assert mu.min() == pytest.approx(fat) and mu.max() <= fibrous * (1 + 1e-12)
    mid = mesh.points[mesh.cells].mean(axis=1)
    n = s.background.nodules[0]
    inside = np.linalg.norm(mid - n.centre, axis=1) < 0.3 * n.radius
    if inside.any():  # a cell well inside the nodule carries (about) the nodule's modulus
        assert mu[inside].max() == pytest.approx(fibrous, rel=0.05)
    d_nod = np.min([np.linalg.norm(mid - n.centre, axis=1) - n.radius
                    for n in (*s.background.nodules, *s.tumours)], axis=0)
    size = np.ptp(mesh.points[mesh.cells], axis=1).max(axis=1)
    free = d_nod > size  # away from every sphere: fat, over the ribs too (they are no modulus)
    assert free.sum() > 50 and np.all(mu[free] == pytest.approx(fat))
    np.testing.assert_allclose(bulk / mu, s.material.bulk_ratio())


@pytest.mark.parametrize('centre', [(0.0, 0.0), (0.0, 0.015), (0.012, -0.02)])
def test_the_mesh_floor_follows_the_ribs_and_is_clamped(centre):
    s = load_scene(NODULAR)
    mesh = scene_mesh(s, centre, s.mesh.probe_cells)
    ribs = s.background.ribs
    n2 = len(mesh.skin)
    base = mesh.points[:n2]  # the bottom layer: the clamped wall
    assert set(range(n2)) <= set(mesh.fixed.tolist())
    top = surface_height(base[:, 1], base[:, 2], s.radii)
    want = rib_floor(base[:, 1], base[:, 2], ribs, np.maximum(top, mesh.points[mesh.skin, 0]))
    np.testing.assert_allclose(base[:, 0], want, atol=1e-12)
    # over a rib's line, under the loaded area, the wall stands at the rib's top
    on = np.array([min(abs(z - r.z) for r in ribs) < 1e-4 for z in base[:, 2]])
    near = on & (np.hypot(base[:, 1], base[:, 2]) < 0.03)
    assert np.allclose(base[near, 0], ribs[0].top)
    # between the ribs it is the chest wall x = 0, and every cell keeps a positive thickness
    between = np.array([min(abs(z - r.z) for r in ribs) > ribs[0].radius for z in base[:, 2]])
    assert between.sum() > 10 and np.all(base[between, 0] == 0.0)
    assert np.all(mesh.points[mesh.skin, 0] > base[:, 0])


def test_rib_floor_is_the_section_above_the_wall_and_keeps_its_cover():
    rib = Rib(name='rib0', z=0.015, radius=0.006, top=0.009, cover=0.005)
    z = np.array([0.0, 0.015, 0.015 + 0.0052, 0.015 + 0.0059, 0.021, 0.015])
    top = np.array([0.03, 0.03, 0.03, 0.03, 0.03, 0.011])
    got = rib_floor(np.zeros_like(z), z, [rib], top)
    assert got[0] == 0.0 and got[1] == pytest.approx(0.009)
    # a half-ellipse 12 mm wide rising 9 mm: continuous, down to the wall at its edges
    assert got[2] == pytest.approx(0.009 * np.sqrt(1 - (5.2 / 6) ** 2))
    assert 0.0 < got[3] < got[2] and got[4] == 0.0
    assert got[5] == pytest.approx(0.006)  # thin breast: lowered to stay 5 mm under the skin


def test_a_rib_with_a_modulus_is_refused_in_one_line(raw):
    d = _with(raw, ribs={**raw['background']['ribs'], 'youngs_kPa': 2000})
    with pytest.raises(SceneError, match=r'background\.ribs\.youngs_kPa: ribs are rigid') as e:
        parse_scene(d)
    assert '\n' not in str(e.value)


def test_a_lesion_free_nodular_scene_is_graded_and_swept_per_point():
    free = load_scene(SCENE_DIR / 'nod_s_fatty_free.yaml')
    assert not free.ring_diameters and free.background is not None and free.graded
    assert load_scene(SCENE_DIR / 'lib_free_s_fatty.yaml').graded  # rings, no background
    assert not load_scene(SCENE_DIR / 'normal.yaml').background
