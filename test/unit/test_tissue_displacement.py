"""Probe-frame polar sampling and harmonics of skin displacement fields (no FE solve)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from haptic_anfis.tissue.displacement import (from_harmonics, polar_coordinates, probe_frame,
                                              sample_polar, to_harmonics)
from haptic_anfis.tissue.fe import scene_mesh
from haptic_anfis.tissue.geometry import indentation_direction
from haptic_anfis.tissue.scene import load_scene


@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(
    lambda v: np.linalg.norm(v) > 1e-3))
def test_probe_frame_is_orthonormal_right_handed(v):
    f = probe_frame(v)
    np.testing.assert_allclose(f @ f.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(f) == pytest.approx(1.0)
    np.testing.assert_allclose(f[0], np.asarray(v) / np.linalg.norm(v))


@pytest.mark.parametrize('bad', [[0, 0, 0], [np.nan, 0, 1]])
def test_probe_frame_rejects_degenerate_direction(bad):
    with pytest.raises(ValueError, match='direction'):
        probe_frame(bad)


@settings(max_examples=20, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=5, max_size=5))
def test_harmonics_roundtrip(c):
    theta = 2 * np.pi * np.arange(32) / 32
    coeffs = np.array(c)[:, None] * np.ones((5, 3))
    samples = from_harmonics(coeffs, theta)
    np.testing.assert_allclose(to_harmonics(samples), coeffs, atol=1e-12)


@pytest.mark.parametrize('where', ['centre', 'slope'])
def test_sample_polar_recovers_a_known_field_on_the_fe_skin(where):
    # An analytic field, given at the FE skin nodes, comes back on the polar grid.
    s = load_scene()
    p = np.array([0.0, 0.0, 0.0]) if where == 'centre' else np.array([0.0, -0.03, 0.018])
    from haptic_anfis.tissue.scene import surface_height

    p[0] = surface_height(p[1:2], p[2:3], s.radii)[0]
    m = scene_mesh(s, p[1:], 6)
    d = indentation_direction(s, p[None])[0]
    frame = probe_frame(d)
    X = m.points[m.skin]
    _, rho, th = polar_coordinates(X, p, frame)
    a = s.probe_radius
    def ax(r, t):  # smooth through the axis: the angular part grows like r
        return 0.01 * np.exp(-(r / (2 * a)) ** 2) * (1 + 0.2 * (r / a) * np.cos(t))

    axial = ax(rho, th)
    radial = -0.002 * rho / (rho + a)
    basis_r = np.cos(th)[:, None] * frame[1] + np.sin(th)[:, None] * frame[2]
    u = axial[:, None] * frame[0] + radial[:, None] * basis_r
    local = np.full(len(m.points), -1)
    local[m.skin] = np.arange(len(m.skin))
    r_grid = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0]) * a
    out = sample_polar(X, local[m.skin_quads], u[None], p, d, r_grid)
    tg = 2 * np.pi * np.arange(32) / 32
    want_ax = ax(r_grid[:, None], tg[None])
    # linear interpolation on 2 mm (probe) to ~6 mm (3 a) cells, field length scale 16 mm
    np.testing.assert_allclose(out[0, :, :, 0], want_ax, atol=3e-4)
    np.testing.assert_allclose(out[0, 1:, :, 1], (-0.002 * r_grid / (r_grid + a))[1:, None]
                               * np.ones((1, 32)), atol=1e-4)
    assert np.abs(out[0, :, :, 2]).max() < 1e-4
    c = to_harmonics(out)
    assert np.abs(c[0, :, 1, 0] - 0.2 * r_grid / a * c[0, :, 0, 0]).max() < 2e-4  # cos(theta)
