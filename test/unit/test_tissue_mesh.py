"""Per-point hexahedral meshes: probe outline on r = a, valid cells, tumour volume fractions."""
import numpy as np
import pytest

from haptic_anfis.tissue.fe import scene_domain, scene_moduli
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.mesh import (Domain, build_mesh, disc_ogrid, layer_fractions,
                                      moebius_for_circle, ring_radii, tumour_fractions)
from haptic_anfis.tissue.scene import load_scene


@pytest.mark.parametrize('p, a', [(0j, 0.1), (0.5 + 0.2j, 0.12), (-0.7j, 0.1), (0.75, 0.2)])
def test_moebius_maps_inner_circle_onto_probe_outline(p, a):
    c, s = moebius_for_circle(p, a)
    w = s * np.exp(1j * np.linspace(0, 2 * np.pi, 50))
    z = (w + c) / (1 + np.conj(c) * w)
    np.testing.assert_allclose(np.abs(z - p), a, atol=1e-12)


def test_ogrid_orientation_and_rim():
    w, q, n_core = disc_ogrid(6, 0.2)
    z = w[q]
    area = 0.5 * np.sum(z.real * np.roll(z.imag, -1, 1) - np.roll(z.real, -1, 1) * z.imag, 1)
    assert np.all(area > 0)
    assert np.isclose(area.sum(), np.pi, rtol=0.02)  # polygonal disc
    assert np.abs(w[:n_core]).max() == pytest.approx(0.2)
    assert ring_radii(0.2, 6)[-1] == pytest.approx(1.0)


def test_layer_fractions():
    f = layer_fractions(0.045, 0.0015, 1.25)
    assert f[0] == 0 and f[-1] == 1 and np.all(np.diff(f) > 0)
    assert (f[-1] - f[-2]) * 0.045 == pytest.approx(0.0015, rel=0.3)


@pytest.mark.parametrize('which', ['centre', 'edge', 'tumour'])
def test_scene_mesh_valid_with_nodes_on_probe_circle(which):
    import felupe as fem

    s = load_scene()
    pts = loading_points(s)
    r = np.hypot(pts[:, 1], pts[:, 2])
    i = {'centre': np.argmin(r), 'edge': np.argmax(r),
         'tumour': np.argmin(np.hypot(pts[:, 1] - 0.015, pts[:, 2] + 0.010))}[which]
    p = pts[i]
    m = build_mesh(scene_domain(s), (p[1], p[2]), s.probe_radius, s.mesh.coarse_probe_cells)
    fp = m.points[m.footprint]
    rho = np.hypot(fp[:, 1] - p[1], fp[:, 2] - p[2])
    assert rho.max() == pytest.approx(s.probe_radius, rel=1e-9)  # outline ON r = a
    n = s.mesh.coarse_probe_cells
    assert np.sum(np.isclose(rho, s.probe_radius, rtol=1e-9)) == 4 * n
    # footprint nodes lie on the undeformed skin
    rx, ry, rz = s.radii
    np.testing.assert_allclose((fp[:, 0] / rx) ** 2 + (fp[:, 1] / ry) ** 2 + (fp[:, 2] / rz) ** 2,
                               1.0, atol=1e-9)
    region = fem.RegionHexahedron(fem.Mesh(m.points, m.cells, 'hexahedron'))
    assert np.all(region.dV > 0)
    assert np.all(m.points[m.fixed][:, 0] <= s.radii[0])
    mu, bulk = scene_moduli(s, m)
    assert np.all(mu >= s.material.shear * (1 - 1e-12)) and np.allclose(bulk / mu, bulk[0] / mu[0])


def test_mesh_is_finest_under_the_probe():
    s = load_scene()
    m = build_mesh(scene_domain(s), (0.03, 0.0), s.probe_radius, 6)
    X = m.points[m.cells].mean(1)
    size = np.ptp(m.points[m.cells][:, :, 1], axis=1)
    near = np.hypot(X[:, 1] - 0.03, X[:, 2]) < 0.01
    far = np.hypot(X[:, 1] - 0.03, X[:, 2]) > 0.06
    assert size[near].mean() < 0.5 * size[far].mean()


def test_tumour_fraction_recovers_sphere_volume():
    dom = Domain(ry=0.05, rz=0.05, height=lambda y, z: np.full(np.shape(y), 0.04), fix_rim=False)
    m = build_mesh(dom, (0.0, 0.0), 0.008, 8)
    c, r = (0.025, 0.0, 0.0), 0.008
    frac = tumour_fractions(m, [(c, r)])[:, 0]
    import felupe as fem

    vol = fem.RegionHexahedron(fem.Mesh(m.points, m.cells, 'hexahedron')).dV.sum(0)
    assert (frac * vol).sum() == pytest.approx(4 / 3 * np.pi * r ** 3, rel=0.05)


def test_elliptic_base_keeps_probe_outline_round():
    import felupe as fem

    ry, rz = 0.069, 0.055
    dom = Domain(ry=ry, rz=rz, height=lambda y, z: 0.045 * np.sqrt(
        np.clip(1 - (y / 0.07) ** 2 - (z / 0.056) ** 2, 0.01, None)))
    m = build_mesh(dom, (0.01, -0.02), 0.008, 6)
    fp = m.points[m.footprint]
    rho = np.hypot(fp[:, 1] - 0.01, fp[:, 2] + 0.02)
    assert rho.max() == pytest.approx(0.008, rel=1e-9)
    region = fem.RegionHexahedron(fem.Mesh(m.points, m.cells, 'hexahedron'))
    assert np.all(region.dV > 0)


def test_separate_depth_and_outer_grading():
    # edge grading split into radial-inside, radial-outside (outer_refine) and depth (depth_refine)
    w3, q3, _ = disc_ogrid(6, 0.2, refine=3)
    w0, q0, _ = disc_ogrid(6, 0.2, refine=3, outer_refine=0)
    assert len(w0) < len(w3)
    r3 = np.unique(np.round(np.abs(w3[np.abs(w3) > 0.2 * (1 + 1e-9)]), 12))
    r0 = np.unique(np.round(np.abs(w0[np.abs(w0) > 0.2 * (1 + 1e-9)]), 12))
    assert np.log(r3[0] / 0.2) == pytest.approx(0.5 * np.pi / 6 / 8)  # dq / 2^3 outside
    assert np.log(r0[0] / 0.2) == pytest.approx(0.5 * np.pi / 6)  # no grading
    dom = Domain(ry=0.1, rz=0.1, height=lambda y, z: np.full(np.shape(y), 0.04), fix_rim=False)
    m_d = build_mesh(dom, (0.0, 0.0), 0.008, 6, refine=2, depth_refine=0)
    m_2 = build_mesh(dom, (0.0, 0.0), 0.008, 6, refine=2)
    assert len(m_d.points) < len(m_2.points)
    assert np.sort(np.unique(m_2.points[:, 0]))[-2] > np.sort(np.unique(m_d.points[:, 0]))[-2]


def test_edge_offset_pulls_the_footprint_outline_inside_the_probe():
    # alpha = 0.2 of the first outer cell (~ a * pi / (2 n)) inside a; n = 6 -> a / 1.05236
    dom = Domain(ry=0.1, rz=0.1, height=lambda y, z: np.full(np.shape(y), 0.04), fix_rim=False)
    m0 = build_mesh(dom, (0.0, 0.0), 0.008, 6, refine=0)
    m2 = build_mesh(dom, (0.0, 0.0), 0.008, 6, refine=0, edge_offset=0.2)
    r2 = np.hypot(*m2.points[m2.footprint][:, 1:].T)
    assert m0.footprint_radius == pytest.approx(0.008)
    assert m2.footprint_radius == pytest.approx(0.008 / (1 + 0.2 * np.pi / 12))
    assert r2.max() == pytest.approx(m2.footprint_radius, rel=1e-9)
    assert len(m2.footprint) == len(m0.footprint)  # same topology, smaller outline
    with pytest.raises(ValueError, match='edge_offset'):
        build_mesh(dom, (0.0, 0.0), 0.008, 6, edge_offset=1.0)
