"""ContactDetector against brute force over all faces: closest point to 1e-12 m, same sign."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings, strategies as st

from contact_reference import (brute_closest, dome, feature_points, probe_points, star_mesh,
                               winding_number, with_slivers)
from haptic_anfis.contact import ContactDetector, MeshWarning

ATOL = 1e-12  # [m]


def detector(mesh, direction=None):
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', MeshWarning)
        return ContactDetector(mesh, direction=direction)


def check_exact(mesh, P, closed=True, sign_margin=1e-9):
    """Closest points (query and query_many) match brute force; signs match the winding number."""
    det = detector(mesh)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    ref_q, ref_d, unique = brute_closest(V, F, P, return_unique=True)
    b = det.query_many(P)
    # Where the closest point is not unique (equidistant faces), any of them is right: the
    # distance check below covers it.
    np.testing.assert_allclose(b.point[unique], ref_q[unique], rtol=0, atol=ATOL)
    np.testing.assert_allclose(np.abs(b.signed_distance), ref_d, rtol=0, atol=ATOL)
    # The reported face really holds the point, with the reported barycentrics.
    corners = V[F[b.triangle]]
    np.testing.assert_allclose(np.einsum('ij,ijk->ik', b.barycentric, corners), b.point,
                               rtol=0, atol=ATOL)
    assert np.all(b.barycentric >= 0) and np.allclose(b.barycentric.sum(axis=1), 1)
    np.testing.assert_allclose(np.linalg.norm(b.normal, axis=1), 1.0, atol=1e-12)
    # Single queries agree with the batch bit for bit (same kernel, hints only prune).
    for i in range(0, len(P), max(1, len(P) // 25)):
        r = det.query(P[i])
        np.testing.assert_array_equal(r.point, b.point[i])
        assert r.signed_distance == b.signed_distance[i]
    if closed:
        inside = winding_number(V, F, P) > 0.5
        far = ref_d > sign_margin
        bad = np.flatnonzero(far & ((b.signed_distance < 0) != inside))
        assert bad.size == 0, f'{bad.size} wrong signs, e.g. p={P[bad[0]]!r}'
    return det, b


def test_icosphere_metres():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    check_exact(mesh, probe_points(mesh, 400, seed=1, near=1e-3))
    check_exact(mesh, feature_points(mesh, 60, seed=2, offset=1e-4))


def test_small_triangles_in_metres():
    # 0.2 mm triangles expressed in metres: where trimesh's fixed tolerances go wrong.
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.002)
    check_exact(mesh, probe_points(mesh, 300, seed=3, near=1e-5))
    check_exact(mesh, feature_points(mesh, 40, seed=4, offset=1e-6))


def test_millimetre_sized_coordinates():
    # The same sphere with coordinates in mm (a mesh built without unit conversion) is still exact.
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=50.0)
    check_exact(mesh, probe_points(mesh, 200, seed=5, near=1.0), sign_margin=1e-6)


def test_dome_with_large_thin_chest_wall_fan():
    # The closed dome's chest-wall disc is a fan of 70 mm x 2 mm slivers next to small dome faces.
    mesh = dome(n_theta=20, n_phi=100)
    det, b = check_exact(mesh, probe_points(mesh, 400, seed=6, near=2e-3))
    check_exact(mesh, feature_points(mesh, 60, seed=7, offset=1e-4))
    # Points right above and below the chest wall near the fan's apex.
    P = np.array([[1e-7, 1e-5, 0.0], [-1e-7, 1e-5, 0.0], [1e-3, 0.0, 0.0], [-1e-3, 0, 0]])
    check_exact(mesh, P)


def test_star_mesh_sharp_edges_and_vertices():
    # Non-convex with sharp ridges: a face normal alone gets the sign wrong near edges/vertices.
    mesh = star_mesh(seed=3)
    check_exact(mesh, probe_points(mesh, 400, seed=8, near=2e-3))
    check_exact(mesh, feature_points(mesh, 100, seed=9, offset=1e-3))


def test_zero_area_faces():
    mesh = with_slivers(star_mesh(seed=4), n_split=30, seed=1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        ContactDetector(mesh)
    assert any('zero area' in str(w.message) for w in caught)
    check_exact(mesh, probe_points(mesh, 300, seed=10, near=2e-3))
    # Right at the inserted midpoints (T-junctions), on and off the surface.
    mids = np.asarray(mesh.vertices)[len(star_mesh(seed=4).vertices):]
    rng = np.random.default_rng(0)
    P = np.vstack([mids, mids + rng.normal(size=mids.shape) * 1e-3,
                   mids + rng.normal(size=mids.shape) * 1e-6])
    check_exact(mesh, P)


def test_unmerged_duplicate_vertices_like_stl():
    # Every face with its own corners (as STL stores them): no connectivity at all.
    src = star_mesh(seed=5)
    soup = trimesh.Trimesh(np.asarray(src.vertices)[np.asarray(src.faces)].reshape(-1, 3),
                           np.arange(3 * len(src.faces)).reshape(-1, 3), process=False)
    with pytest.warns(MeshWarning, match='duplicate'):
        ContactDetector(soup)
    check_exact(soup, feature_points(src, 80, seed=11, offset=1e-3))
    check_exact(soup, probe_points(src, 200, seed=12, near=1e-3))


def test_open_mesh():
    mesh = dome(n_theta=15, n_phi=60, closed=False)
    with pytest.warns(MeshWarning, match='not watertight'):
        ContactDetector(mesh)
    P = probe_points(mesh, 300, seed=13, near=2e-3)
    det, b = check_exact(mesh, P, closed=False)
    # Where the closest point is inside a face, the sign is that face's side.
    interior = np.all(b.barycentric > 1e-6, axis=1)
    n = np.asarray(mesh.face_normals)[b.triangle]
    side = np.einsum('ij,ij->i', P - b.point, n)
    assert interior.sum() > 50
    assert np.all(np.sign(b.signed_distance[interior]) == np.sign(side[interior]))


def test_points_exactly_on_vertices_and_edges():
    mesh = star_mesh(seed=6)
    det = detector(mesh)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    for v in V[:50]:
        r = det.query(v)
        np.testing.assert_array_equal(r.point, v)
        assert r.signed_distance == 0.0 and not r.in_contact
    for a, b in zip(V[F[:50, 0]], V[F[:50, 1]]):
        r = det.query(0.5 * (a + b))
        assert abs(r.signed_distance) < 1e-15


@settings(derandomize=True, max_examples=150, deadline=None)
@given(st.tuples(*[st.floats(-0.08, 0.08, allow_nan=False)] * 3),
       st.sampled_from(['vertex', 'edge', 'free']), st.floats(-2e-3, 2e-3))
def test_property_star(xyz, where, off):
    mesh = _STAR
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    p = np.array(xyz)
    if where != 'free':  # snap to the nearest vertex / edge midpoint, then step off by `off`
        pts = V if where == 'vertex' else 0.5 * (V[F[:, 0]] + V[F[:, 1]])
        k = np.argmin(np.sum((pts - p) ** 2, axis=1))
        p = pts[k] + off * (p - pts[k]) / max(np.linalg.norm(p - pts[k]), 1e-300)
    r = _STAR_DET.query(p)
    ref_q, ref_d, unique = brute_closest(V, F, p[None], return_unique=True)
    assert abs(abs(r.signed_distance) - ref_d[0]) <= ATOL
    if unique[0]:
        np.testing.assert_allclose(r.point, ref_q[0], rtol=0, atol=ATOL)
    if ref_d[0] > 1e-9:
        assert (r.signed_distance < 0) == (winding_number(V, F, p[None])[0] > 0.5)


_STAR = star_mesh(seed=7, subdivisions=2)
_STAR_DET = detector(_STAR)


def test_query_many_empty_and_shapes():
    det = detector(star_mesh(seed=8, subdivisions=1))
    b = det.query_many(np.empty((0, 3)))
    assert len(b) == 0 and b.point.shape == (0, 3)
    b = det.query_many([[0.1, 0.0, 0.0]])
    assert b.point.shape == (1, 3) and b.triangle.dtype == np.int64


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_non_finite_probe_is_a_clear_error(bad):
    det = detector(star_mesh(seed=8, subdivisions=1))
    with pytest.raises(ValueError, match='p: probe position must be finite'):
        det.query([0.0, bad, 0.0])
    P = np.zeros((5, 3))
    P[3, 2] = bad
    with pytest.raises(ValueError, match='P: .*first row 3'):
        det.query_many(P)
    with pytest.raises(ValueError, match=r'p: expected shape'):
        det.query([0.0, 0.0])


@pytest.mark.parametrize('facing', [0, 1, -1])
def test_raycast_matches_brute_force(facing):
    # The front-to-back ray traversal prunes by the nearest hit so far: same t as all faces.
    from contact_reference import brute_raycast
    for mesh in (dome(n_theta=20, n_phi=80), star_mesh(seed=9)):
        det = detector(mesh)
        V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        rng = np.random.default_rng(20 + facing)
        P = probe_points(mesh, 150, seed=21, near=5e-3)
        D = rng.normal(size=(len(P), 3))
        D[:50] = np.tile([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], (17, 1))[:50]
        D /= np.linalg.norm(D, axis=1, keepdims=True)
        for p, d, tmin in zip(P, D, rng.choice([0.0, -0.01], len(P))):
            ref = brute_raycast(V, F, p, d, tmin, np.inf, facing)
            hit = det._raycast(p, d, tmin, np.inf, facing)
            assert (hit is None) == (ref is None)
            if ref is not None:
                assert abs(hit[1] - ref) <= 1e-12


def test_closest_falls_back_to_depth_first_when_the_queue_is_full(monkeypatch):
    # The best-first queue holds _HEAP nodes; beyond that a subtree is scanned depth-first.
    # Run closest() as Python with a 2-entry queue so that path runs, against brute force.
    from haptic_anfis.contact import bvh
    mesh = star_mesh(seed=10)
    det = detector(mesh)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    P = probe_points(mesh, 40, seed=22, near=2e-3)
    ref_q, ref_d = brute_closest(V, F, P)
    monkeypatch.setattr(bvh, '_HEAP', 2)
    for p, d in zip(P, ref_d):
        r = bvh.closest.py_func(det._tri, det._box, det._node, p[0], p[1], p[2], -1,
                                0.0, 0.0, 0.0, np.inf)
        assert abs(np.sqrt(r[1]) - d) <= ATOL
