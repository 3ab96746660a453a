"""Mesh files that name their problem (issue 21 items 4-5, issue 22's STL part): a wrong
``mesh_unit`` (the shipped millimetre surface read as metres, a metres mesh read as millimetres),
random bytes as ``.stl``, and an ASCII STL whose name holds a Latin-1 byte."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from haptic_anfis.contact import load_mesh
from haptic_anfis.contact.mesh_io import check_extent

DEFAULT_STL = __import__('haptic_anfis').__path__[0] + '/data/default_surface.stl'


def test_default_surface_in_its_unit_loads():
    m = load_mesh(DEFAULT_STL, unit='mm')
    assert 0.05 < np.ptp(m.vertices, axis=0).max() < 0.5


def test_millimetre_surface_read_as_metres_names_mesh_unit():
    with pytest.raises(ValueError, match=r"default_surface.stl: the surface is .* m across read "
                                         r"with mesh_unit 'm', implausible .*set mesh_unit: mm"):
        load_mesh(DEFAULT_STL, unit='m')


def test_metres_mesh_read_as_millimetres_names_mesh_unit(tmp_path):
    m = load_mesh(DEFAULT_STL, unit='mm')
    p = tmp_path / 'in_metres.stl'
    m.export(p)  # coordinates now in metres
    with pytest.raises(ValueError, match=r"µm across read with mesh_unit 'mm'.*set mesh_unit: m"):
        load_mesh(p, unit='mm')
    assert np.allclose(load_mesh(p, unit='m').vertices, m.vertices, atol=1e-7)


def test_extent_bounds_and_a_scale_no_unit_fixes():
    v = np.array([[0.0, 0.0, 0.0], [5e-6, 0, 0], [0, 5e-6, 0]])  # 5 µm: no unit makes it a breast
    with pytest.raises(ValueError, match="check the file's scale and mesh_unit"):
        check_extent(v, 'm', 'tiny')
    assert check_extent(v * 2000.0, 'm') == pytest.approx(0.01)  # the lower bound is allowed


def test_random_bytes_as_stl_is_not_a_mesh_file(tmp_path):
    p = tmp_path / 'noise.stl'
    p.write_bytes(np.random.default_rng(22).bytes(4096))
    with pytest.raises(ValueError, match=r'noise.stl: not a mesh file') as e:
        load_mesh(p)
    assert 'charset_normalizer' not in str(e.value)


def test_ascii_stl_with_a_latin1_name_loads(tmp_path):
    text = ('solid caf\xe9\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n'
            '   vertex 50 0 0\n   vertex 0 50 0\n  endloop\n endfacet\nendsolid caf\xe9\n')
    p = tmp_path / 'cafe.stl'
    p.write_bytes(text.encode('latin-1'))
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # one open triangle: not watertight, warned
        m = load_mesh(p, unit='mm')
    np.testing.assert_allclose(m.vertices, [[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]])
