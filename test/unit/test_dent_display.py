"""The drawn surface in patches: the dent under the probe at the contact depth, nothing far away,
and the patches restored when the probe lifts (no ROS)."""
import numpy as np
import pytest

from deformation_fixture import A, synthetic
from haptic_anfis.tissue.deformation import DeformationModel
from haptic_anfis.tissue.dent_display import DentSurface
from haptic_anfis.tissue.geometry import surface_mesh

RADII = (0.045, 0.07, 0.07)


@pytest.fixture(scope='module')
def surface():
    mesh = surface_mesh(RADII)
    model = DeformationModel(taper=4.0, reach=5.0).fit(synthetic())
    return DentSurface(np.asarray(mesh.vertices), np.asarray(mesh.faces), model)


def _drawn(surface, patches):
    """{face id: (3, 3) drawn corners} for the given patches."""
    out = {}
    for p in patches:
        faces = surface.patch_faces[p.index]
        for k, f in enumerate(faces):
            out[int(f)] = p.corners[3 * k:3 * k + 3]
    return out


@pytest.mark.parametrize('yz', [(0.0, 0.0), (0.02, -0.015)])
def test_dent_depth_under_probe_and_nothing_far(surface, yz):
    y, z = yz
    x = RADII[0] * np.sqrt(1 - (y / RADII[1]) ** 2 - (z / RADII[2]) ** 2)
    c, d, depth = np.array([x, y, z]), np.array([-1.0, 0.0, 0.0]), 0.012
    changed = surface.update(c, d, depth)
    drawn = _drawn(surface, changed)
    V, F = surface.vertices, surface.faces
    rho = np.hypot(V[:, 1] - y, V[:, 2] - z)
    skin = V[:, 0] > 0  # the chest-wall disc (x = 0) is clamped: it never moves
    under = np.flatnonzero((rho <= A * (1 - 1e-9)) & skin)
    assert len(under) > 10
    # every vertex under the probe is drawn exactly at the contact depth along the direction
    for f, corners in drawn.items():
        for k, vid in enumerate(F[f]):
            if rho[vid] <= A * (1 - 1e-9) and skin[vid]:
                np.testing.assert_allclose(corners[k], V[vid] + depth * d, atol=1e-12)
    assert set(np.flatnonzero(np.isin(F, under).any(axis=1))) <= set(drawn)
    # nothing moves beyond the reach or on the chest wall; far patches are not re-sent
    np.testing.assert_array_equal(surface.displacement[(rho > 5 * A) | ~skin], 0.0)
    far = {k for k, f in enumerate(surface.patch_faces) if np.all(rho[F[f]] > 5 * A)}
    assert far and not far & {p.index for p in changed}
    # every drawn corner is within the tolerance of the model's dent
    for f, corners in drawn.items():
        assert np.abs(corners - (V[F[f]] + surface.displacement[F[f]])).max() <= 1e-4
    # a steady press re-sends nothing; a slightly deeper one re-sends the footprint, exactly
    assert surface.update(c, d, depth) == []
    deeper = surface.update(c, d, depth + 1e-6)
    assert deeper
    for f, corners in _drawn(surface, deeper).items():
        for k, vid in enumerate(F[f]):
            if rho[vid] <= A * (1 - 1e-9) and skin[vid]:
                np.testing.assert_allclose(corners[k], V[vid] + (depth + 1e-6) * d, atol=1e-12)
    changed = changed + deeper
    # lifting restores exactly the dented patches
    restored = surface.update(None, None, 0.0)
    assert sorted(p.index for p in restored) == sorted({p.index for p in changed})
    for f, corners in _drawn(surface, restored).items():
        np.testing.assert_array_equal(corners, V[F[f]])
    assert surface.update(None, None, 0.0) == []


def test_patches_cover_every_face_once(surface):
    faces = np.concatenate(surface.patch_faces)
    assert sorted(faces.tolist()) == list(range(len(surface.faces)))
    allp = surface.all_patches()
    assert sum(len(p.corners) for p in allp) == 3 * len(surface.faces)
    assert all(p.colours.shape == (len(p.corners), 4) for p in allp)


def test_bad_surface_rejected():
    model = DeformationModel().fit(synthetic())
    with pytest.raises(ValueError, match='faces'):
        DentSurface(np.zeros((3, 3)), np.zeros((1, 4), dtype=int), model)
    with pytest.raises(ValueError, match='patch_size'):
        DentSurface(np.zeros((3, 3)), np.zeros((1, 3), dtype=int), model, patch_size=0.0)


def test_the_dent_feed_sends_a_late_subscriber_everything_and_otherwise_only_what_changed():
    """DentFeed, frame by frame: nothing while nobody draws it, every patch when a subscriber
    joins, the changed patches when the contact moves, nothing for the contact already drawn,
    and a new surface (a case switch) dented afresh."""
    from haptic_anfis.tissue.dent_display import DentFeed
    mesh = surface_mesh(RADII)
    model = DeformationModel(taper=4.0, reach=5.0).fit(synthetic())
    s = DentSurface(np.asarray(mesh.vertices), np.asarray(mesh.faces), model)
    x = RADII[0]
    press = (np.array([x, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0]), 0.008)
    feed = DentFeed(subscribers=0)
    assert feed.frame(None, press, 1) == []   # no surface yet
    assert feed.frame(s, press, 0) == [] and feed.frames == 0   # nobody draws it
    joined = feed.frame(s, None, 1)   # a subscriber joins, probe lifted
    assert len(joined) == s.n_patches and feed.frames == 0
    dented = feed.frame(s, press, 1)
    assert 0 < len(dented) < s.n_patches and feed.frames == 1 and feed.last is press
    assert feed.frame(s, press, 1) == [] and feed.frames == 1   # the contact drawn
    lifted = feed.frame(s, None, 1)
    assert {p.index for p in lifted} == {p.index for p in dented} and feed.frames == 2
    other = DentSurface(np.asarray(mesh.vertices), np.asarray(mesh.faces), model)
    assert len(feed.frame(other, press, 1)) == len(dented)   # the new surface dented afresh
