"""Mesh files: units, transforms, formats, and clear errors/warnings for bad input."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from contact_reference import brute_closest, dome
from haptic_anfis.contact import ContactDetector, MeshWarning, load_mesh


def _mm(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    return trimesh.Trimesh(np.asarray(mesh.vertices) * 1000.0, mesh.faces, process=False)


@pytest.mark.parametrize('ext', ['ply', 'obj', 'stl', 'off'])
def test_formats_in_millimetres_match_metres(tmp_path, ext):
    mesh_m = dome(n_theta=10, n_phi=40)
    path = tmp_path / f'dome.{ext}'
    _mm(mesh_m).export(path)
    with warnings.catch_warnings():
        warnings.simplefilter('error', MeshWarning)  # a closed dome: no warning, STL included
        det = ContactDetector.from_file(path, unit='mm', direction=(-1, 0, 0))
    raw = trimesh.load(path, force='mesh', process=False)
    V = np.asarray(raw.vertices) * 1e-3  # what the file holds (STL is float32), in metres
    assert np.abs(V).max() < 0.08
    P = np.random.default_rng(0).uniform(-0.02, 0.06, (50, 3))
    ref_q, ref_d = brute_closest(V, np.asarray(raw.faces), P)
    b = det.query_many(P)
    np.testing.assert_allclose(b.point, ref_q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.abs(b.signed_distance), ref_d, rtol=0, atol=1e-12)
    r = det.query([0.040, 0.0, 0.0])
    assert r.in_contact and abs(r.depth - 0.005) < 1e-6


def test_metres_unit_and_transform(tmp_path):
    mesh_m = dome(n_theta=10, n_phi=40)
    # The file is in a scanner frame: rotated 90 deg about z and shifted; the transform undoes it.
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    shift = np.array([0.1, 0.2, 0.3])
    scanned = trimesh.Trimesh(np.asarray(mesh_m.vertices) @ R.T + shift, mesh_m.faces,
                              process=False)
    path = tmp_path / 'scan.ply'
    scanned.export(path)
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = -R.T @ shift
    det = ContactDetector.from_file(path, unit='m', transform=T)
    ref = ContactDetector(mesh_m)
    P = np.random.default_rng(1).uniform(-0.02, 0.06, (30, 3))
    # PLY stores float32: the round trip through the scanner frame is good to ~1e-8 m.
    np.testing.assert_allclose(det.query_many(P).point, ref.query_many(P).point, atol=1e-7)


def _write(path, text):
    path.write_text(text)
    return path


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match='nope.stl'):
        ContactDetector.from_file(tmp_path / 'nope.stl')


def test_bad_unit_and_transform(tmp_path):
    path = tmp_path / 'd.ply'
    dome(n_theta=4, n_phi=8).export(path)
    with pytest.raises(ValueError, match=r"d.ply: unit must be one of \['m', 'mm'\], got 'cm'"):
        load_mesh(path, unit='cm')
    with pytest.raises(ValueError, match='transform must be a finite'):
        load_mesh(path, unit='m', transform=np.eye(3))
    with pytest.raises(ValueError, match='keep orientation'):
        load_mesh(path, unit='m', transform=np.diag([-1.0, 1.0, 1.0, 1.0]))


def test_unreadable_and_empty_files(tmp_path):
    for name, text in [('empty.stl', ''), ('junk.obj', 'this is not a mesh\n'),
                       ('points.obj', 'v 0 0 0\nv 1 0 0\nv 0 1 0\n'), ('junk.ply', 'ply\nxx\n')]:
        with pytest.raises(ValueError, match=name.replace('.', r'\.')):
            ContactDetector.from_file(_write(tmp_path / name, text))


def test_non_finite_vertices(tmp_path):
    path = _write(tmp_path / 'nan.obj', 'v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n')
    with pytest.raises(ValueError, match='nan.obj: expected finite vertex coordinates'):
        ContactDetector.from_file(path)
    mesh = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, np.inf, 0]], [[0, 1, 2]], process=False)
    with pytest.raises(ValueError, match='mesh: expected finite'):
        ContactDetector(mesh)


def test_all_degenerate_faces(tmp_path):
    path = _write(tmp_path / 'flat.obj', 'v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n')
    with pytest.raises(ValueError, match='flat.obj: expected faces with non-zero area'):
        ContactDetector.from_file(path)


def test_no_faces():
    with pytest.raises(ValueError, match='mesh: expected a triangle mesh with at least one face'):
        ContactDetector(trimesh.Trimesh(np.zeros((3, 3)), np.zeros((0, 3), int), process=False))


def test_warnings_open_and_duplicates(tmp_path):
    # One square as two triangles with the shared corners duplicated: open, duplicate vertices.
    path = _write(tmp_path / 'sq.obj', 'v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 0 0\nv 1 1 0\nv 0 1 0\n'
                                       'f 1 2 3\nf 4 5 6\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        det = ContactDetector.from_file(path, unit='m')
    msgs = [str(w.message) for w in caught if issubclass(w.category, MeshWarning)]
    assert any('sq.obj' in m and 'not watertight' in m for m in msgs), msgs
    assert any('sq.obj' in m and '2 duplicate vertices' in m for m in msgs), msgs
    assert sum('sq.obj' in m for m in msgs) == len(msgs) == 2  # warned once, naming the file
    # Still works: above the square is outside (+z normal), below inside.
    assert det.query([0.5, 0.5, 0.1]).signed_distance == pytest.approx(0.1)
    assert det.query([0.5, 0.5, -0.1]).signed_distance == pytest.approx(-0.1)
    assert det.query([0.5, 0.5, 0.0]).signed_distance == 0.0


def test_bad_direction():
    mesh = dome(n_theta=4, n_phi=8)
    for bad in [(0, 0, 0), (1, 0), (np.nan, 0, 1)]:
        with pytest.raises(ValueError, match='direction'):
            ContactDetector(mesh, direction=bad)
    det = ContactDetector(mesh, direction=(-2.0, 0, 0))
    np.testing.assert_array_equal(det.direction, [-1.0, 0.0, 0.0])
